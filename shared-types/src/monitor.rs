//! The task monitored online (issue 46): a bounded MTL formula over signed distances to sets, evaluated
//! on the measured state every step, with the running lower and upper bound of its robustness at time 0
//! and the verdict at the step it is decided. The optional section 14 of an image stores the program
//! ([`MonitorProgram`]); the evaluator's state ([`Monitor`]) lives in a caller-provided word arena whose
//! size the program fixes ([`MonitorProgram::words`]), so a firmware sizes it at build time and a firmware
//! built without a monitor links none of this.
//!
//! # Semantics (Def 2.17 on the sampled run, windows in samples)
//! The run's samples are x(0), x(1), …, x(N) (N, the horizon in samples, is stored); the formula is in
//! negation normal form (the host pushes every negation to the atoms), so every operator is monotone:
//! * an atom is a signed distance, positive inside: a half-space `b − aᵀy` (‖a‖ = 1 by the host), a box
//!   (inside the least distance to a face, outside minus the Euclidean distance), a ball `r − ‖y − c‖`,
//!   a polytope by its rows (`min_i b_i − a_iᵀy`, exact inside, a lower bound of the distance outside),
//!   each over listed state coordinates y; a negated atom is its opposite; −0 is stored as +0, so every
//!   value is a zero-free-of-sign f32 and min and max are exact selections;
//! * F[a,b] φ (t) = max over j ∈ [t+a, min(t+b, N)] of φ(j) (−∞ over an empty window), G its dual (min,
//!   +∞);
//! * φ U[a,b] ψ (t) = max over j ∈ [t+a, min(t+b, N)] of min(ψ(j), min over t < i < j of φ(i)), R its dual.
//!
//! # Online evaluation, exact with delay
//! Each node emits its exact value at t as soon as it is decided by the samples so far, one value per
//! step in the steady state: at step k = t + hor (the node's horizon: 0 for an atom; the larger of the
//! children's for ∧ and ∨; b + the child's for F and G; b + max(hor ψ, hor φ − 1) for U and R, or hor ψ when
//! b = 0), and every remaining value at step N (the windows then end at N). F and G keep a monotone deque
//! of the window (amortised O(1) per step); U and R keep the sliding minimum of φ over (t, t + a) and a
//! two-stack queue of the clamp maps f_j(y) = max(ψ(j), min(φ(j), y)) of j ∈ [t + a, e − 1], whose
//! composition applied to ψ(e) is the until over the window (the host's `mtl` derivation, streamed). A
//! node emits only the values its parent reads (`need`), so at step N the work is bounded by the formula's
//! windows. A node read at t = 0 only (every top-level operator) never slides: F and G keep the front of
//! the deque, U and R the composition of their maps and no more of φ and ψ than the children's lag (ψ's
//! history from 0 when a = 0, whose head ψ(0) is read at the end).
//!
//! # Bounds before the verdict
//! The root's value at 0 is bracketed every step by sound bounds (every unknown sample may be anything):
//! ∧ and ∨ combine their children's bounds at the same time (an emitted child value is exact); F's lower
//! bound is the largest value of its window emitted so far and its upper bound +∞ (G dually); U's bounds
//! are the composed maps applied to −∞ (or to the next ψ already emitted) and to +∞, each capped by the
//! known part of the minimum of φ over (t, t + a). A temporal node does not look into its children's own
//! bounds, so the bracket is sound but not always the tightest; it closes on the exact value at the step
//! the root emits it. The verdict is `Satisfied` once the lower bound is positive, `Violated` once the
//! upper bound is negative, and `Boundary` if the decided value is 0.
//!
//! All arithmetic is f32: the atoms' sums, products and square roots (libm's `sqrtf`, correctly rounded),
//! and otherwise min, max and negation, which are exact. The host's reference of the same semantics
//! (computed by definition, not incrementally) gives the same bits.

use crate::capacity::MAX_N;
use crate::raw::{f32_at, u32_at};

/// Largest number of atoms of a monitor program.
pub const MAX_MONITOR_ATOMS: usize = 32;
/// Largest number of nodes of a monitor program (each keeps a small state in [`Monitor`]).
pub const MAX_MONITOR_NODES: usize = 32;
/// Largest horizon N in samples.
pub const MAX_MONITOR_SAMPLES: usize = 1 << 16;
/// Largest number of rows of a polytope atom.
pub const MAX_MONITOR_ROWS: usize = 64;
/// Largest arena a program may ask for, in 32-bit words (256 KiB).
pub const MAX_MONITOR_WORDS: usize = 1 << 16;

/// Words of the section's fixed header: n, N, atoms, nodes, atom words.
const HEADER_WORDS: usize = 5;
/// Words of one node record: op, first child (or atom), second child (or negation), a, b.
pub const NODE_WORDS: usize = 5;

/// Atom kinds (the first word of an atom record).
pub const ATOM_HALFSPACE: u32 = 1;
/// A box over listed coordinates.
pub const ATOM_BOX: u32 = 2;
/// A Euclidean ball over listed coordinates.
pub const ATOM_BALL: u32 = 3;
/// A polytope by its rows over listed coordinates.
pub const ATOM_POLYTOPE: u32 = 4;

/// Node operators (the first word of a node record).
pub const OP_ATOM: u32 = 1;
/// ⊤ (+∞).
pub const OP_TRUE: u32 = 2;
/// ⊥ (−∞).
pub const OP_FALSE: u32 = 3;
/// Binary ∧ (min).
pub const OP_AND: u32 = 4;
/// Binary ∨ (max).
pub const OP_OR: u32 = 5;
/// F[a,b].
pub const OP_EVENTUALLY: u32 = 6;
/// G[a,b].
pub const OP_ALWAYS: u32 = 7;
/// U[a,b] (first child φ, second ψ).
pub const OP_UNTIL: u32 = 8;
/// R[a,b] (first child φ, second ψ).
pub const OP_RELEASE: u32 = 9;

pub use crate::error::MonitorError;

/// The verdict on the task so far.
#[repr(u8)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Verdict {
    /// Not decided yet.
    Pending = 0,
    /// The robustness is certainly positive.
    Satisfied = 1,
    /// The robustness is certainly negative.
    Violated = 2,
    /// Decided, and exactly 0.
    Boundary = 3,
}

/// What the monitor reports after a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Report {
    /// Lower bound of the robustness at time 0.
    pub lo: f32,
    /// Upper bound of the robustness at time 0.
    pub hi: f32,
    /// The verdict.
    pub verdict: Verdict,
}

impl Report {
    /// The report of the bounds `lo ≤ hi`: satisfied once `lo` is positive, violated once `hi` is
    /// negative, `Boundary` when decided at exactly 0 (module doc).
    pub fn of_bounds(lo: f32, hi: f32) -> Self {
        let verdict = if lo > 0.0 {
            Verdict::Satisfied
        } else if hi < 0.0 {
            Verdict::Violated
        } else if lo == hi {
            Verdict::Boundary
        } else {
            Verdict::Pending
        };
        Report { lo, hi, verdict }
    }
}

/// A validated monitor program, borrowed from its section body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MonitorProgram<'a> {
    body: &'a [u8],
    n: usize,
    horizon: usize,
    atoms: usize,
    nodes: usize,
    /// Word offset of each atom's record (atoms ≤ MAX_MONITOR_ATOMS).
    atom_at: [u32; MAX_MONITOR_ATOMS],
    /// Word offset of the first node record.
    nodes_at: usize,
}

#[inline(always)]
fn word(body: &[u8], i: usize) -> usize {
    u32_at(body, i) as usize
}

/// Words of atom record `kind` with `d` coordinates and, for a polytope, `rows` rows (0 if unknown).
fn atom_len(kind: u32, d: usize, rows: usize) -> Option<usize> {
    match kind {
        ATOM_HALFSPACE => Some(2 + 2 * d + 1),
        ATOM_BOX => Some(2 + 3 * d),
        ATOM_BALL => Some(2 + 2 * d + 1),
        ATOM_POLYTOPE => Some(3 + d + rows * d + rows),
        _ => None,
    }
}

/// A node's static description, decoded once.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Op {
    op: u32,
    c1: usize,
    c2: usize,
    a: usize,
    b: usize,
}

impl<'a> MonitorProgram<'a> {
    /// The program a section body holds, validated for an image of state dimension `n` (module doc;
    /// refused with the first thing wrong).
    pub fn decode(body: &'a [u8], n: usize) -> Result<Self, MonitorError> {
        if !body.len().is_multiple_of(4) || body.len() < 4 * HEADER_WORDS {
            return Err(MonitorError::Length);
        }
        let total = body.len() / 4;
        let (dn, horizon, atoms, nodes, atom_words) = (
            word(body, 0),
            word(body, 1),
            word(body, 2),
            word(body, 3),
            word(body, 4),
        );
        if dn != n
            || n == 0
            || n > MAX_N
            || horizon >= MAX_MONITOR_SAMPLES
            || atoms > MAX_MONITOR_ATOMS
            || nodes == 0
            || nodes > MAX_MONITOR_NODES
        {
            return Err(MonitorError::Dims);
        }
        let nodes_at = HEADER_WORDS.saturating_add(atom_words);
        if nodes_at.saturating_add(nodes * NODE_WORDS) != total {
            return Err(MonitorError::Length);
        }
        let mut p = MonitorProgram {
            body,
            n,
            horizon,
            atoms,
            nodes,
            atom_at: [0; MAX_MONITOR_ATOMS],
            nodes_at,
        };
        // Atoms, back to back.
        let mut at = HEADER_WORDS;
        for i in 0..atoms {
            let bad = MonitorError::Atom(i as u16);
            let kind = u32_at(body, at);
            let d = word(body, at + 1);
            if d == 0 || d > n {
                return Err(bad);
            }
            let rows = if kind == ATOM_POLYTOPE {
                word(body, at + 2 + d)
            } else {
                0
            };
            if kind == ATOM_POLYTOPE && (rows == 0 || rows > MAX_MONITOR_ROWS) {
                return Err(bad);
            }
            let len = atom_len(kind, d, rows).ok_or(bad)?;
            if at + len > nodes_at {
                return Err(bad);
            }
            for j in 0..d {
                if word(body, at + 2 + j) >= n {
                    return Err(bad);
                }
            }
            let floats_from = at + 2 + d + usize::from(kind == ATOM_POLYTOPE);
            for j in floats_from..at + len {
                if !f32_at(body, j).is_finite() {
                    return Err(bad);
                }
            }
            match kind {
                ATOM_BOX => {
                    for j in 0..d {
                        if f32_at(body, floats_from + j) > f32_at(body, floats_from + d + j) {
                            return Err(bad);
                        }
                    }
                }
                ATOM_BALL => {
                    if f32_at(body, floats_from + d) < 0.0 {
                        return Err(bad);
                    }
                }
                _ => {}
            }
            if let Some(slot) = p.atom_at.get_mut(i) {
                *slot = at as u32;
            }
            at += len;
        }
        if at != nodes_at {
            return Err(MonitorError::Length);
        }
        // Nodes: children before parents, each node but the last read by exactly one parent.
        let mut read = [false; MAX_MONITOR_NODES];
        for i in 0..nodes {
            let bad = MonitorError::Node(i as u16);
            let o = p.op(i);
            let child =
                |c: usize, read: &mut [bool; MAX_MONITOR_NODES]| -> Result<(), MonitorError> {
                    match read.get_mut(c) {
                        Some(r) if c < i && !*r => {
                            *r = true;
                            Ok(())
                        }
                        _ => Err(bad),
                    }
                };
            match o.op {
                OP_ATOM => {
                    if o.c1 >= atoms || o.c2 > 1 || o.a != 0 || o.b != 0 {
                        return Err(bad);
                    }
                }
                OP_TRUE | OP_FALSE => {
                    if o.c1 != 0 || o.c2 != 0 || o.a != 0 || o.b != 0 {
                        return Err(bad);
                    }
                }
                OP_AND | OP_OR => {
                    if o.c1 == o.c2 || o.a != 0 || o.b != 0 {
                        return Err(bad);
                    }
                    child(o.c1, &mut read)?;
                    child(o.c2, &mut read)?;
                }
                OP_EVENTUALLY | OP_ALWAYS => {
                    if o.c2 != 0 || o.a > o.b || o.b >= MAX_MONITOR_SAMPLES {
                        return Err(bad);
                    }
                    child(o.c1, &mut read)?;
                }
                OP_UNTIL | OP_RELEASE => {
                    if o.c1 == o.c2 || o.a > o.b || o.b >= MAX_MONITOR_SAMPLES {
                        return Err(bad);
                    }
                    child(o.c1, &mut read)?;
                    child(o.c2, &mut read)?;
                }
                _ => return Err(bad),
            }
        }
        for (i, r) in read.iter().enumerate().take(nodes.saturating_sub(1)) {
            if !*r {
                return Err(MonitorError::Node(i as u16));
            }
        }
        if p.words() > MAX_MONITOR_WORDS {
            return Err(MonitorError::Dims);
        }
        Ok(p)
    }

    /// The section body.
    pub fn body(&self) -> &'a [u8] {
        self.body
    }

    /// The horizon N in samples.
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// Number of atoms.
    pub fn atoms(&self) -> usize {
        self.atoms
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.nodes
    }

    fn op(&self, i: usize) -> Op {
        let at = self.nodes_at + i * NODE_WORDS;
        Op {
            op: u32_at(self.body, at),
            c1: word(self.body, at + 1),
            c2: word(self.body, at + 2),
            a: word(self.body, at + 3),
            b: word(self.body, at + 4),
        }
    }

    /// Atom `i`'s signed distance at the state `x` (module doc), −0 as +0; 0 for a bad index.
    pub fn atom(&self, i: usize, x: &[f32]) -> f32 {
        let at = self.atom_at.get(i).copied().unwrap_or(0) as usize;
        let body = self.body;
        let kind = u32_at(body, at);
        let d = word(body, at + 1).min(MAX_N);
        let y = |j: usize| x.get(word(body, at + 2 + j)).copied().unwrap_or(0.0);
        let f = at + 2 + d;
        let v = match kind {
            ATOM_HALFSPACE => {
                let mut s = 0.0f32;
                for j in 0..d {
                    s += f32_at(body, f + j) * y(j);
                }
                f32_at(body, f + d) - s
            }
            ATOM_BOX => {
                let (mut depth, mut out2, mut outside) = (f32::INFINITY, 0.0f32, false);
                for j in 0..d {
                    let (lo, hi, v) = (f32_at(body, f + j), f32_at(body, f + d + j), y(j));
                    let e = if v < lo {
                        lo - v
                    } else if v > hi {
                        v - hi
                    } else {
                        0.0
                    };
                    if e > 0.0 {
                        outside = true;
                        out2 += e * e;
                    }
                    depth = depth.min((v - lo).min(hi - v));
                }
                if outside {
                    -libm::sqrtf(out2)
                } else {
                    depth
                }
            }
            ATOM_BALL => {
                let mut s = 0.0f32;
                for j in 0..d {
                    let e = y(j) - f32_at(body, f + j);
                    s += e * e;
                }
                f32_at(body, f + d) - libm::sqrtf(s)
            }
            ATOM_POLYTOPE => {
                let rows = word(body, f).min(MAX_MONITOR_ROWS);
                let (a0, b0) = (f + 1, f + 1 + rows * d);
                let mut least = f32::INFINITY;
                for r in 0..rows {
                    let mut s = 0.0f32;
                    for j in 0..d {
                        s += f32_at(body, a0 + r * d + j) * y(j);
                    }
                    least = least.min(f32_at(body, b0 + r) - s);
                }
                least
            }
            _ => 0.0,
        };
        v + 0.0
    }

    /// The static plan of every node (horizon, values needed, parent, buffers in the arena), its state
    /// written to the front of `arena` when given ([`PLAN_WORDS`] per node, the buffers after); returns
    /// the arena's words. Only small per-node arrays live on the stack.
    fn plan_into(&self, mut arena: Option<&mut [u32]>) -> usize {
        let mut hor = [0usize; MAX_MONITOR_NODES];
        let mut need = [0usize; MAX_MONITOR_NODES];
        let mut parent = [NONE; MAX_MONITOR_NODES];
        let cap = self.horizon + 1;
        let get = |a: &[usize; MAX_MONITOR_NODES], i: usize| a.get(i).copied().unwrap_or(0);
        // Horizons, children first.
        for i in 0..self.nodes {
            let o = self.op(i);
            let h = match o.op {
                OP_AND | OP_OR => get(&hor, o.c1).max(get(&hor, o.c2)),
                OP_EVENTUALLY | OP_ALWAYS => o.b.saturating_add(get(&hor, o.c1)),
                OP_UNTIL | OP_RELEASE => until_hor(o.a, o.b, get(&hor, o.c1), get(&hor, o.c2)),
                _ => 0,
            };
            if let Some(x) = hor.get_mut(i) {
                *x = h.min(2 * MAX_MONITOR_SAMPLES);
            }
        }
        // Values needed, root first: the root's value at 0.
        if let Some(x) = need.get_mut(self.nodes.saturating_sub(1)) {
            *x = 1;
        }
        for i in (0..self.nodes).rev() {
            let o = self.op(i);
            let n = get(&need, i);
            let mut set = |c: usize, v: usize| {
                if let (Some(x), Some(p)) = (need.get_mut(c), parent.get_mut(c)) {
                    *x = v.min(cap);
                    *p = i;
                }
            };
            match o.op {
                OP_AND | OP_OR => {
                    set(o.c1, n);
                    set(o.c2, n);
                }
                OP_EVENTUALLY | OP_ALWAYS => set(o.c1, n + o.b),
                OP_UNTIL | OP_RELEASE => {
                    let l = if phi_unread(o.a, o.b) {
                        0
                    } else {
                        (n + o.b).saturating_sub(1)
                    };
                    set(o.c1, l);
                    set(o.c2, n + o.b);
                }
                _ => {}
            }
        }
        // The nodes' states, then their buffers.
        let mut words = self.nodes * PLAN_WORDS;
        for i in 0..self.nodes {
            let o = self.op(i);
            let (h, h1, h2) = (get(&hor, i), get(&hor, o.c1), get(&hor, o.c2));
            let mut bufs = [Buf::default(); 5];
            let mut alloc = |slot: usize, entries: usize, per: usize| {
                if let Some(b) = bufs.get_mut(slot) {
                    *b = Buf {
                        off: words as u32,
                        cap: entries as u32,
                        head: 0,
                        len: 0,
                    };
                }
                words += entries * per;
            };
            match o.op {
                OP_AND | OP_OR => {
                    alloc(0, (h2.saturating_sub(h1)).min(cap) + 2, 1);
                    alloc(1, (h1.saturating_sub(h2)).min(cap) + 2, 1);
                }
                // A node read at t = 0 only (`need` 1, every top-level operator) never slides its window:
                // the front of F's deque is all it needs, and U needs neither stack of maps (only their
                // composition), nor more of its histories than the children's lag.
                OP_EVENTUALLY | OP_ALWAYS if get(&need, i) <= 1 => alloc(0, 2, 2),
                OP_EVENTUALLY | OP_ALWAYS => alloc(0, (o.b - o.a).min(cap) + 2, 2),
                OP_UNTIL | OP_RELEASE if get(&need, i) <= 1 => {
                    alloc(0, h2.saturating_sub(h1).min(cap) + 3, 1);
                    let psi = if o.a == 0 {
                        // The head ψ(0) stays in the history, so it keeps the window.
                        (o.b + h.saturating_sub(o.b + h2)).min(cap) + 2
                    } else {
                        h1.saturating_sub(h2).min(cap) + 3
                    };
                    alloc(1, psi, 1);
                    alloc(2, 2, 2);
                    alloc(3, 0, 4);
                    alloc(4, 0, 2);
                }
                OP_UNTIL | OP_RELEASE => {
                    let slack_l = (h + 1).saturating_sub(o.b + h1);
                    let slack_r = h.saturating_sub(o.b + h2);
                    // φ's history (t, e − 1 + slack], ψ's [t + a, e + slack], the minimum of φ over
                    // (t, t + a), the two stacks of maps over [t + max(a, 1), e − 1].
                    alloc(0, (o.b + slack_l).min(cap) + 2, 1);
                    alloc(1, (o.b - o.a + slack_r).min(cap) + 2, 1);
                    alloc(2, o.a.min(cap) + 2, 2);
                    let w = (o.b - o.a).min(cap) + 2;
                    alloc(3, w, 4);
                    alloc(4, w, 2);
                }
                _ => {}
            }
            if let Some(a) = arena.as_deref_mut() {
                let p = Plan {
                    hor: h,
                    need: get(&need, i),
                    parent: parent.get(i).copied().unwrap_or(NONE),
                    back: IDENTITY,
                    b1: bufs[0],
                    b2: bufs[1],
                    b3: bufs[2],
                    b4: bufs[3],
                    b5: bufs[4],
                    ..Plan::default()
                };
                p.store(a, i);
            }
        }
        words
    }

    /// The arena [`Monitor::new`] needs, in 32-bit words.
    pub fn words(&self) -> usize {
        self.plan_into(None)
    }

    /// The arena in bytes plus the evaluator's own state ([`Monitor`], in this build's layout: a 32-bit
    /// target's is smaller, its `usize` being 4 bytes), what `inspect` reports as the monitor's RAM.
    pub fn ram_bytes(&self) -> usize {
        4 * self.words() + core::mem::size_of::<Monitor<'static>>()
    }
}

/// U, R: b + max(ψ's, φ's − 1), or b + ψ's when φ is never read ([`phi_unread`]; module doc).
pub(crate) fn until_hor(a: usize, b: usize, hl: usize, hr: usize) -> usize {
    if phi_unread(a, b) {
        b.saturating_add(hr)
    } else {
        b.saturating_add(hr.max(hl.saturating_sub(1)))
    }
}

/// U[a,b], R[a,b] read no value of φ when no witness j has a sample strictly between t and j (b ≤ 1).
pub(crate) fn phi_unread(a: usize, b: usize) -> bool {
    a <= 1 && b <= 1
}

/// The first map of U's queue at t: φ(i) counts only for t < i, so with a = 0 the witness t itself is a
/// separate head term ψ(t) and the maps start at t + 1.
fn first_map(t: usize, a: usize) -> usize {
    t + a.max(1)
}

const NONE: usize = usize::MAX;

/// A ring buffer in the arena: `cap` entries of a fixed number of words from word `off`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Buf {
    off: u32,
    cap: u32,
    head: u32,
    len: u32,
}

/// A node's static plan and running state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Plan {
    hor: usize,
    need: usize,
    parent: usize,
    /// Values emitted (the next t).
    emitted: usize,
    /// The value emitted in this pass, if any.
    out: Option<f32>,
    /// Children's values received (F, G: fed; U, R: φ and ψ; ∧, ∨: unused).
    got1: usize,
    got2: usize,
    /// U, R: the next φ index fed to the minimum over (t, t + a), the next map index.
    m_next: usize,
    map_next: usize,
    /// U, R: the first map index in the queue; the back stack's composed map.
    q_lo: usize,
    back: (f32, f32),
    b1: Buf,
    b2: Buf,
    b3: Buf,
    b4: Buf,
    b5: Buf,
}

/// Words of one node's state in the arena ([`Plan::load`], [`Plan::store`]).
const PLAN_WORDS: usize = 33;

impl Plan {
    /// Node `i`'s state from the arena (zeros outside it).
    fn load(arena: &[u32], i: usize) -> Plan {
        const ZERO: [u32; PLAN_WORDS] = [0; PLAN_WORDS];
        // One slice of the node's words, so each field below is read without a bounds check.
        let w: &[u32; PLAN_WORDS] = arena
            .get(i * PLAN_WORDS..(i + 1) * PLAN_WORDS)
            .and_then(|s| s.try_into().ok())
            .unwrap_or(&ZERO);
        let z = |j: usize| w[j] as usize;
        let buf = |j: usize| Buf {
            off: w[j],
            cap: w[j + 1],
            head: w[j + 2],
            len: w[j + 3],
        };
        Plan {
            hor: z(0),
            need: z(1),
            parent: if w[2] == u32::MAX { NONE } else { z(2) },
            emitted: z(3),
            out: (w[4] == 1).then(|| f32::from_bits(w[5])),
            got1: z(6),
            got2: z(7),
            m_next: z(8),
            map_next: z(9),
            q_lo: z(10),
            back: (f32::from_bits(w[11]), f32::from_bits(w[12])),
            b1: buf(13),
            b2: buf(17),
            b3: buf(21),
            b4: buf(25),
            b5: buf(29),
        }
    }

    /// Node `i`'s state into the arena (counters are below 2¹⁷, so they fit a word).
    fn store(&self, arena: &mut [u32], i: usize) {
        let Some(w) = arena
            .get_mut(i * PLAN_WORDS..(i + 1) * PLAN_WORDS)
            .and_then(|s| <&mut [u32; PLAN_WORDS]>::try_from(s).ok())
        else {
            return;
        };
        let u = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
        w[0] = u(self.hor);
        w[1] = u(self.need);
        w[2] = if self.parent == NONE {
            u32::MAX
        } else {
            u(self.parent)
        };
        w[3] = u(self.emitted);
        w[4] = u32::from(self.out.is_some());
        w[5] = self.out.map_or(0, f32::to_bits);
        w[6] = u(self.got1);
        w[7] = u(self.got2);
        w[8] = u(self.m_next);
        w[9] = u(self.map_next);
        w[10] = u(self.q_lo);
        w[11] = self.back.0.to_bits();
        w[12] = self.back.1.to_bits();
        for (j, b) in [self.b1, self.b2, self.b3, self.b4, self.b5]
            .iter()
            .enumerate()
        {
            w[13 + 4 * j] = b.off;
            w[14 + 4 * j] = b.cap;
            w[15 + 4 * j] = b.head;
            w[16 + 4 * j] = b.len;
        }
    }
}

/// The evaluator's state over a borrowed arena (module doc): the nodes' states and buffers live in the
/// arena, so this struct stays small whatever the program.
pub struct Monitor<'a> {
    prog: MonitorProgram<'a>,
    arena: &'a mut [u32],
    /// The nodes' records, decoded once (read every pass).
    ops: [Op; MAX_MONITOR_NODES],
    /// The next sample index.
    k: usize,
    atom_vals: [f32; MAX_MONITOR_ATOMS],
    /// The root's value at 0 once emitted.
    root: Option<f32>,
    last: Report,
}

#[inline(always)]
fn neg(x: f32) -> f32 {
    -x + 0.0
}

/// The clamp map y ↦ max(α, min(β, y)) composed: (outer ∘ inner).
#[inline(always)]
fn compose(outer: (f32, f32), inner: (f32, f32)) -> (f32, f32) {
    let c = |y: f32| outer.0.max(outer.1.min(y));
    (c(inner.0), c(inner.1))
}

#[inline(always)]
fn apply(m: (f32, f32), y: f32) -> f32 {
    m.0.max(m.1.min(y))
}

const IDENTITY: (f32, f32) = (f32::NEG_INFINITY, f32::INFINITY);

impl Buf {
    /// Word of entry `i` (i < len ≤ cap, head < cap, so one wrap at most: no division).
    #[inline(always)]
    fn slot(&self, i: usize, per: usize) -> usize {
        let mut s = self.head as usize + i;
        if s >= self.cap as usize {
            s -= self.cap as usize;
        }
        self.off as usize + s * per
    }
}

fn get(arena: &[u32], at: usize) -> f32 {
    f32::from_bits(arena.get(at).copied().unwrap_or(0))
}

fn put(arena: &mut [u32], at: usize, v: f32) {
    if let Some(w) = arena.get_mut(at) {
        *w = v.to_bits();
    }
}

fn push(arena: &mut [u32], b: &mut Buf, per: usize, vals: &[f32]) {
    if b.len >= b.cap {
        return;
    }
    let at = b.slot(b.len as usize, per);
    for (j, &v) in vals.iter().enumerate().take(per) {
        put(arena, at + j, v);
    }
    b.len += 1;
}

fn at(arena: &[u32], b: &Buf, i: usize, per: usize, j: usize) -> f32 {
    get(arena, b.slot(i, per) + j)
}

fn pop_front(b: &mut Buf) {
    if b.len > 0 {
        b.head += 1;
        if b.head >= b.cap {
            b.head = 0;
        }
        b.len -= 1;
    }
}

fn pop_back(b: &mut Buf) {
    b.len = b.len.saturating_sub(1);
}

/// A monotone deque of (index, value) for the sliding maximum: pop stale indices below `from`, dominated
/// values at the back, then push.
fn deque_push_max(arena: &mut [u32], b: &mut Buf, from: usize, idx: usize, v: f32) {
    deque_drop_below(arena, b, from);
    while b.len > 0 && at(arena, b, b.len as usize - 1, 2, 1) <= v {
        pop_back(b);
    }
    push(arena, b, 2, &[f32::from_bits(idx as u32), v]);
}

fn deque_drop_below(arena: &[u32], b: &mut Buf, from: usize) {
    while b.len > 0 && (at(arena, b, 0, 2, 0).to_bits() as usize) < from {
        pop_front(b);
    }
}

/// The front value of a max-deque among indices from `from`, or −∞, leaving the deque as it is (the
/// bounds read it; the next [`deque_max`] drops what this skips).
fn deque_peek(arena: &[u32], b: &Buf, from: usize) -> f32 {
    for i in 0..b.len as usize {
        if (at(arena, b, i, 2, 0).to_bits() as usize) >= from {
            return at(arena, b, i, 2, 1);
        }
    }
    f32::NEG_INFINITY
}

/// The front value of a max-deque after dropping indices below `from`, or −∞.
fn deque_max(arena: &[u32], b: &mut Buf, from: usize) -> f32 {
    deque_drop_below(arena, b, from);
    if b.len > 0 {
        at(arena, b, 0, 2, 1)
    } else {
        f32::NEG_INFINITY
    }
}

impl<'a> Monitor<'a> {
    /// A monitor at its first sample over `arena` (at least [`MonitorProgram::words`] words).
    pub fn new(prog: MonitorProgram<'a>, arena: &'a mut [u32]) -> Result<Self, MonitorError> {
        if arena.len() < prog.words() {
            return Err(MonitorError::Arena);
        }
        prog.plan_into(Some(arena));
        let mut ops = [Op::default(); MAX_MONITOR_NODES];
        for (i, o) in ops.iter_mut().enumerate().take(prog.nodes) {
            *o = prog.op(i);
        }
        Ok(Monitor {
            prog,
            arena,
            ops,
            k: 0,
            atom_vals: [0.0; MAX_MONITOR_ATOMS],
            root: None,
            last: Report {
                lo: f32::NEG_INFINITY,
                hi: f32::INFINITY,
                verdict: Verdict::Pending,
            },
        })
    }

    /// The program.
    pub fn program(&self) -> &MonitorProgram<'a> {
        &self.prog
    }

    /// The sample index the next [`Monitor::update`] takes.
    pub fn samples(&self) -> usize {
        self.k
    }

    /// The last report.
    pub fn report(&self) -> Report {
        self.last
    }

    /// Back to the first sample.
    pub fn reset(&mut self) {
        let prog = self.prog;
        prog.plan_into(Some(self.arena));
        self.k = 0;
        self.root = None;
        self.last = Report {
            lo: f32::NEG_INFINITY,
            hi: f32::INFINITY,
            verdict: Verdict::Pending,
        };
    }

    /// Take the sample x(k) (n values, the plant's state) and report. After sample N the report stays.
    pub fn update(&mut self, x: &[f32]) -> Report {
        let horizon = self.prog.horizon;
        if self.k > horizon {
            return self.last;
        }
        for i in 0..self.prog.atoms {
            if let Some(v) = self.atom_vals.get_mut(i) {
                *v = self.prog.atom(i, x);
            }
        }
        let end = self.k == horizon;
        // One pass in the steady state; at the end, passes until nothing is emitted (each emits at most
        // one value per node, bounded by the values needed).
        let mut passes = 0usize;
        loop {
            let mut any = false;
            for i in 0..self.prog.nodes {
                // In the passes after the first (the end's), a node that has emitted every value it
                // owes, has no output to clear and no child output to take has nothing left to do.
                if passes > 0 && self.idle(i) {
                    continue;
                }
                any |= self.process(i, passes == 0);
            }
            passes += 1;
            if !end || !any || passes > 2 * MAX_MONITOR_SAMPLES + 2 {
                break;
            }
        }
        self.k += 1;
        let root = self.prog.nodes.saturating_sub(1);
        let (lo, hi) = match self.root {
            Some(v) => (v, v),
            None => self.bounds(root, 0),
        };
        self.last = Report::of_bounds(lo, hi);
        self.last
    }

    /// Node `i`'s record (a default one past the program's nodes).
    #[inline(always)]
    fn op(&self, i: usize) -> Op {
        self.ops.get(i).copied().unwrap_or_default()
    }

    fn plan(&self, i: usize) -> Plan {
        Plan::load(self.arena, i)
    }

    fn set_plan(&mut self, i: usize, p: &Plan) {
        p.store(self.arena, i);
    }

    /// Whether node `c`'s parent accepts `c`'s next value (backpressure, module doc).
    fn room(&self, c: usize, pc: &Plan) -> bool {
        let parent = pc.parent;
        if parent == NONE || parent >= self.prog.nodes {
            return true;
        }
        let o = self.op(parent);
        // The parent's words read in place ([`Plan::store`]'s layout): emitted, and the buffer of this
        // child (b1 for the first child, b2 for the second: cap, len).
        let w = |j: usize| self.word(parent, j) as usize;
        let (cap, len) = if c == o.c1 {
            (w(14), w(16))
        } else {
            (w(18), w(20))
        };
        match o.op {
            OP_AND | OP_OR | OP_UNTIL | OP_RELEASE => len < cap,
            OP_EVENTUALLY | OP_ALWAYS => pc.emitted <= (w(3) + o.b).min(self.prog.horizon),
            _ => true,
        }
    }

    /// Whether node `i` is done ([`Monitor::update`]'s end passes): every value it owes emitted, no value
    /// of its own from the last pass to clear, and no child value to take. Such a node's turn changes
    /// nothing any other node or the bounds read, so it is skipped; not skipping is always sound, so a
    /// doubt (a child word that is not a node) keeps the turn.
    fn idle(&self, i: usize) -> bool {
        let o = self.op(i);
        let (emitted, need) = (self.word(i, 3) as usize, self.word(i, 1) as usize);
        let done = emitted >= need || emitted > self.prog.horizon;
        let quiet = |c: usize| c < self.prog.nodes && self.word(c, 4) == 0;
        let children = match o.op {
            OP_ATOM | OP_TRUE | OP_FALSE => true,
            OP_EVENTUALLY | OP_ALWAYS => quiet(o.c1),
            _ => quiet(o.c1) && quiet(o.c2),
        };
        done && self.word(i, 4) == 0 && children
    }

    /// Word `j` of node `i`'s state in the arena.
    fn word(&self, i: usize, j: usize) -> u32 {
        self.arena.get(i * PLAN_WORDS + j).copied().unwrap_or(0)
    }

    /// The value node `c` emitted in this pass, if any (its state's words 4 and 5).
    fn out_of(&self, c: usize) -> Option<f32> {
        (self.word(c, 4) == 1).then(|| f32::from_bits(self.word(c, 5)))
    }

    /// One node's turn in a pass: take its children's values, emit at most one of its own. Returns
    /// whether it emitted.
    fn process(&mut self, i: usize, first: bool) -> bool {
        let o = self.op(i);
        let mut p = self.plan(i);
        p.out = None;
        let k = self.k;
        let horizon = self.prog.horizon;
        let t = p.emitted;
        let can = t < p.need && t <= horizon;
        let (out1, out2) = (self.out_of(o.c1), self.out_of(o.c2));
        let child_out = |c: usize| if c == o.c1 { out1 } else { out2 };
        let mut emit: Option<f32> = None;
        match o.op {
            OP_ATOM | OP_TRUE | OP_FALSE => {
                if first && can && t == k {
                    let v = match o.op {
                        OP_TRUE => f32::INFINITY,
                        OP_FALSE => f32::NEG_INFINITY,
                        _ => {
                            let v = self.atom_vals.get(o.c1).copied().unwrap_or(0.0);
                            if o.c2 == 1 {
                                neg(v)
                            } else {
                                v
                            }
                        }
                    };
                    emit = Some(v);
                }
            }
            OP_AND | OP_OR => {
                if let Some(v) = child_out(o.c1) {
                    push(self.arena, &mut p.b1, 1, &[v]);
                }
                if let Some(v) = child_out(o.c2) {
                    push(self.arena, &mut p.b2, 1, &[v]);
                }
                if can && p.b1.len > 0 && p.b2.len > 0 {
                    let (x, y) = (
                        at(self.arena, &p.b1, 0, 1, 0),
                        at(self.arena, &p.b2, 0, 1, 0),
                    );
                    emit = Some(if o.op == OP_AND { x.min(y) } else { x.max(y) });
                }
            }
            OP_EVENTUALLY | OP_ALWAYS => {
                let dual = o.op == OP_ALWAYS;
                if let Some(v) = child_out(o.c1) {
                    let v = if dual { neg(v) } else { v };
                    deque_push_max(self.arena, &mut p.b1, t + o.a, p.got1, v);
                    p.got1 += 1;
                }
                if can {
                    let e = (t + o.b).min(horizon);
                    // An empty window is decided at N, as the schedule of the module doc says.
                    let empty = t + o.a > horizon;
                    if (empty && k == horizon) || (!empty && p.got1 > e) {
                        let v = if empty {
                            f32::NEG_INFINITY
                        } else {
                            deque_max(self.arena, &mut p.b1, t + o.a)
                        };
                        emit = Some(if dual { neg(v) } else { v });
                    }
                }
            }
            OP_UNTIL | OP_RELEASE => {
                let dual = o.op == OP_RELEASE;
                let d = |v: f32| if dual { neg(v) } else { v };
                // Histories: φ from index t + 1, ψ from t + a (earlier values are never read).
                if let Some(v) = child_out(o.c1) {
                    if p.got1 > t {
                        push(self.arena, &mut p.b1, 1, &[d(v)]);
                    }
                    p.got1 += 1;
                }
                if let Some(v) = child_out(o.c2) {
                    if p.got2 >= t + o.a {
                        push(self.arena, &mut p.b2, 1, &[d(v)]);
                    }
                    p.got2 += 1;
                }
                self.until_feed(&o, &mut p);
                if can {
                    let e = (t + o.b).min(horizon);
                    if t + o.a > horizon {
                        if k == horizon {
                            emit = Some(d(f32::NEG_INFINITY));
                        }
                    } else if p.got2 > e && (phi_unread(o.a, o.b) || p.got1 >= e) && p.map_next >= e
                    {
                        let m = deque_max(self.arena, &mut p.b3, t + 1);
                        let q = if e >= first_map(t, o.a) {
                            apply(self.queue_agg(&p), self.history(&p.b2, p.got2, e))
                        } else {
                            f32::NEG_INFINITY
                        };
                        let head = if o.a == 0 {
                            self.history(&p.b2, p.got2, t)
                        } else {
                            f32::NEG_INFINITY
                        };
                        // m is kept negated (a max-deque of −φ): the minimum is −max.
                        emit = Some(d(neg(m).min(head.max(q))));
                    }
                }
            }
            _ => {}
        }
        let mut emitted = false;
        if let Some(v) = emit {
            if self.room(i, &p) {
                if i + 1 == self.prog.nodes {
                    self.root = Some(v);
                }
                p.out = Some(v);
                p.emitted += 1;
                emitted = true;
                match o.op {
                    OP_AND | OP_OR => {
                        pop_front(&mut p.b1);
                        pop_front(&mut p.b2);
                    }
                    OP_UNTIL | OP_RELEASE => self.until_advance(&o, &mut p),
                    _ => {}
                }
            }
        }
        self.set_plan(i, &p);
        emitted
    }

    /// History value at index `j` of a buffer whose last entry is index `got − 1`.
    fn history(&self, b: &Buf, got: usize, j: usize) -> f32 {
        let first = got.saturating_sub(b.len as usize);
        if j < first || j >= got {
            return f32::NEG_INFINITY;
        }
        at(self.arena, b, j - first, 1, 0)
    }

    /// U, R: feed φ into the minimum over (t, t + a) up to t + a − 1 and push maps f_j up to e − 1, from
    /// the histories (values as stored: negated for R).
    fn until_feed(&mut self, o: &Op, p: &mut Plan) {
        let t = p.emitted;
        let horizon = self.prog.horizon;
        let e = (t + o.b).min(horizon);
        if p.m_next < t + 1 {
            p.m_next = t + 1;
        }
        while p.m_next < t + o.a && p.m_next < p.got1 {
            let v = self.history(&p.b1, p.got1, p.m_next);
            // A max-deque of −φ keeps the minimum of φ.
            deque_push_max(self.arena, &mut p.b3, t + 1, p.m_next, neg(v));
            p.m_next += 1;
        }
        let q0 = first_map(t, o.a);
        if p.map_next < q0 {
            p.map_next = q0;
            p.q_lo = p.q_lo.max(q0);
        }
        while p.map_next < e && p.map_next < p.got1 && p.map_next < p.got2 {
            let l = self.history(&p.b1, p.got1, p.map_next);
            let r = self.history(&p.b2, p.got2, p.map_next);
            let f = (r, r.max(l));
            push(self.arena, &mut p.b5, 2, &[f.0, f.1]);
            p.back = compose(p.back, f);
            p.map_next += 1;
        }
        if p.need <= 1 {
            // Read at t = 0 only: what the minimum over (0, a) and the maps have taken is not read again
            // (ψ(0), the head when a = 0, is; and ψ(map_next), the next witness).
            // φ below t + a feeds the minimum (until m_next), φ from there the maps (until map_next).
            let used = if p.m_next >= t + o.a {
                p.map_next
            } else {
                p.m_next
            };
            while p.b1.len > 0 && p.got1 - (p.b1.len as usize) < used {
                pop_front(&mut p.b1);
            }
            while o.a > 0 && p.b2.len > 0 && p.got2 - (p.b2.len as usize) < p.map_next {
                pop_front(&mut p.b2);
            }
        }
    }

    /// U, R: the composed maps of the queue (front stack's top aggregate ∘ back aggregate).
    fn queue_agg(&self, p: &Plan) -> (f32, f32) {
        let front = if p.b4.len > 0 {
            let i = p.b4.len as usize - 1;
            (
                at(self.arena, &p.b4, i, 4, 2),
                at(self.arena, &p.b4, i, 4, 3),
            )
        } else {
            IDENTITY
        };
        compose(front, p.back)
    }

    /// U, R after emitting t (now t + 1): drop the map of index t + a from the queue, φ ≤ t + 1 and ψ
    /// below t + 1 + a from the histories.
    fn until_advance(&mut self, o: &Op, p: &mut Plan) {
        let t = p.emitted; // already advanced
        let q0 = first_map(t, o.a);
        while p.q_lo < q0 && p.q_lo < p.map_next {
            if p.b4.len == 0 {
                // Move the back stack onto the front stack, last first, composing towards the front.
                let mut agg = IDENTITY;
                let n = p.b5.len as usize;
                for r in (0..n).rev() {
                    let f = (
                        at(self.arena, &p.b5, r, 2, 0),
                        at(self.arena, &p.b5, r, 2, 1),
                    );
                    agg = compose(f, agg);
                    push(self.arena, &mut p.b4, 4, &[f.0, f.1, agg.0, agg.1]);
                }
                p.b5.len = 0;
                p.b5.head = 0;
                p.back = IDENTITY;
            }
            pop_back(&mut p.b4);
            p.q_lo += 1;
        }
        p.q_lo = p.q_lo.max(q0);
        // φ history from t + 1, ψ history from t + a.
        while p.b1.len > 0 && p.got1 - (p.b1.len as usize) < t + 1 {
            pop_front(&mut p.b1);
        }
        while p.b2.len > 0 && p.got2 - (p.b2.len as usize) < t + o.a {
            pop_front(&mut p.b2);
        }
    }

    /// Sound bounds of node `i` at its pending time (module doc); exact when it was emitted (the value
    /// then sits in its parent's buffer or was the root's last output).
    fn bounds(&self, i: usize, t: usize) -> (f32, f32) {
        self.bounds_at(i, t, 0)
    }

    fn bounds_at(&self, i: usize, t: usize, depth: usize) -> (f32, f32) {
        const UNKNOWN: (f32, f32) = (f32::NEG_INFINITY, f32::INFINITY);
        if depth > MAX_MONITOR_NODES {
            return UNKNOWN;
        }
        let o = self.op(i);
        let p = self.plan(i);
        if p.emitted > t {
            // Never asked: a parent reads an emitted child's value from its own buffer.
            return UNKNOWN;
        }
        match o.op {
            OP_TRUE => (f32::INFINITY, f32::INFINITY),
            OP_FALSE => (f32::NEG_INFINITY, f32::NEG_INFINITY),
            OP_ATOM => UNKNOWN,
            OP_AND | OP_OR => {
                let c1 = if p.b1.len > 0 {
                    let v = at(self.arena, &p.b1, 0, 1, 0);
                    (v, v)
                } else {
                    self.bounds_at(o.c1, t, depth + 1)
                };
                let c2 = if p.b2.len > 0 {
                    let v = at(self.arena, &p.b2, 0, 1, 0);
                    (v, v)
                } else {
                    self.bounds_at(o.c2, t, depth + 1)
                };
                if o.op == OP_AND {
                    (c1.0.min(c2.0), c1.1.min(c2.1))
                } else {
                    (c1.0.max(c2.0), c1.1.max(c2.1))
                }
            }
            OP_EVENTUALLY | OP_ALWAYS => {
                let lo = deque_peek(self.arena, &p.b1, t + o.a);
                if o.op == OP_ALWAYS {
                    (f32::NEG_INFINITY, neg(lo))
                } else {
                    (lo, f32::INFINITY)
                }
            }
            OP_UNTIL | OP_RELEASE => {
                let known = p.m_next >= (t + o.a).min(self.prog.horizon + 1);
                let m = neg(deque_peek(self.arena, &p.b3, t + 1));
                let agg = self.queue_agg(&p);
                let j = p.map_next;
                let e = (t + o.b).min(self.prog.horizon);
                let maps = e >= first_map(t, o.a);
                let next = if j < p.got2 && j <= e {
                    self.history(&p.b2, p.got2, j)
                } else {
                    f32::NEG_INFINITY
                };
                let (q_lo, q_hi) = if maps {
                    (apply(agg, next), apply(agg, f32::INFINITY))
                } else {
                    (f32::NEG_INFINITY, f32::NEG_INFINITY)
                };
                let head = if o.a > 0 {
                    (f32::NEG_INFINITY, f32::NEG_INFINITY)
                } else if p.got2 > t {
                    let v = self.history(&p.b2, p.got2, t);
                    (v, v)
                } else {
                    (f32::NEG_INFINITY, f32::INFINITY)
                };
                let lo = if known {
                    m.min(head.0.max(q_lo))
                } else {
                    f32::NEG_INFINITY
                };
                let hi = m.min(head.1.max(q_hi));
                if o.op == OP_RELEASE {
                    (neg(hi), neg(lo))
                } else {
                    (lo, hi)
                }
            }
            _ => UNKNOWN,
        }
    }
}
