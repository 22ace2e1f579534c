//! Streaming sliding-window aggregates over windows whose two ends move forward monotonically, each in
//! amortised O(1) per sample:
//!
//! * [`sliding_max`] / [`sliding_min`]: the monotone-deque (wedge) algorithm of Lemire's streaming
//!   max-min filter, generalised from fixed-width windows to any windows `[lo(k), hi(k)]` with `lo`
//!   and `hi` non-decreasing in k (as produced by time windows on non-uniform sample times);
//! * [`ClampQueue`]: a two-stack FIFO aggregating the composition of the monotone maps
//!   f_j(x) = max(ψ_j, min(φ_j, x)), which is how bounded until is evaluated in linear time.

/// Time windows, streamed: for sample k the index range `lo..end` (end exclusive) of samples j with
/// `t[j] − t[k] ∈ [a, b]` (computed in f64 exactly as written). Empty when `lo ≥ end`.
///
/// Both ends are non-decreasing in k: rounded subtraction is monotone, so `fl(t[j] − t[k])` is
/// non-decreasing in j and non-increasing in k for strictly increasing times. Hence two pointers that
/// only move forward, O(n) in total.
pub(crate) struct WindowCursor<'t> {
    t: &'t [f64],
    a: f64,
    b: f64,
    lo: usize,
    end: usize,
}

impl<'t> WindowCursor<'t> {
    pub fn new(t: &'t [f64], a: f64, b: f64) -> Self {
        Self {
            t,
            a,
            b,
            lo: 0,
            end: 0,
        }
    }
    /// The window of sample k; calls must come with k = 0, 1, 2, … in order.
    #[inline(always)]
    pub fn at(&mut self, k: usize) -> (usize, usize) {
        let (t, n) = (self.t, self.t.len());
        // First j with t[j] − t[k] ≥ a (j ≥ k since a ≥ 0 and t strictly increases).
        self.lo = self.lo.max(k);
        while self.lo < n && t[self.lo] - t[k] < self.a {
            self.lo += 1;
        }
        // One past the last j with t[j] − t[k] ≤ b.
        self.end = self.end.max(k);
        while self.end < n && t[self.end] - t[k] <= self.b {
            self.end += 1;
        }
        (self.lo, self.end)
    }
}

/// A monotone deque (wedge) of indices into `v`, kept in a ring buffer that only grows to the largest
/// number of live candidates. `dominates(x, y)` true means a later x makes an earlier y useless (x ≥ y
/// for max, x ≤ y for min).
pub(crate) struct Wedge {
    buf: std::collections::VecDeque<usize>,
}

impl Wedge {
    pub fn new() -> Self {
        Self {
            buf: std::collections::VecDeque::with_capacity(64),
        }
    }
    #[inline(always)]
    pub fn push(&mut self, v: &[f64], j: usize, dominates: impl Fn(f64, f64) -> bool) {
        let x = v[j];
        while let Some(&last) = self.buf.back() {
            if dominates(x, v[last]) {
                self.buf.pop_back();
            } else {
                break;
            }
        }
        self.buf.push_back(j);
    }
    #[inline(always)]
    pub fn expire(&mut self, lo: usize) {
        while let Some(&first) = self.buf.front() {
            if first < lo {
                self.buf.pop_front();
            } else {
                break;
            }
        }
    }
    #[inline(always)]
    pub fn front(&self) -> Option<usize> {
        self.buf.front().copied()
    }
}

fn sliding(
    v: &[f64],
    t: &[f64],
    a: f64,
    b: f64,
    empty: f64,
    dominates: impl Fn(f64, f64) -> bool + Copy,
) -> Vec<f64> {
    let n = v.len();
    let mut out = Vec::with_capacity(n);
    let mut w = WindowCursor::new(t, a, b);
    let mut q = Wedge::new();
    let mut pushed = 0usize;
    for k in 0..n {
        let (lo, end) = w.at(k);
        while pushed < end {
            q.push(v, pushed, dominates);
            pushed += 1;
        }
        q.expire(lo);
        out.push(if lo < end {
            q.front().map_or(empty, |j| v[j])
        } else {
            empty
        });
    }
    out
}

/// out[k] = max of v over the window [a, b] of sample k, −∞ for an empty window.
pub(crate) fn sliding_max(v: &[f64], t: &[f64], a: f64, b: f64) -> Vec<f64> {
    sliding(v, t, a, b, f64::NEG_INFINITY, |x, y| x >= y)
}

/// out[k] = min of v over the window [a, b] of sample k, +∞ for an empty window.
pub(crate) fn sliding_min(v: &[f64], t: &[f64], a: f64, b: f64) -> Vec<f64> {
    sliding(v, t, a, b, f64::INFINITY, |x, y| x <= y)
}

/// The map x ↦ max(alpha, min(beta, x)). These maps are closed under composition:
/// (f∘g)(x) = max(α_f, min(β_f, α_g), min(β_f, β_g, x)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Clamp {
    pub alpha: f64,
    pub beta: f64,
}

impl Clamp {
    pub const ID: Clamp = Clamp {
        alpha: f64::NEG_INFINITY,
        beta: f64::INFINITY,
    };
    /// self ∘ g.
    #[inline(always)]
    pub fn then(self, g: Clamp) -> Clamp {
        Clamp {
            alpha: self.alpha.max(self.beta.min(g.alpha)),
            beta: self.beta.min(g.beta),
        }
    }
}

/// FIFO of indexed [`Clamp`] maps with the aggregate f_front ∘ … ∘ f_back in amortised O(1)
/// (two stacks: the front stack stores suffix compositions, the back stack a running composition).
pub(crate) struct ClampQueue {
    /// Front stack, top = last element = oldest; each entry (index, composition of it and all newer
    /// entries of the front stack).
    front: Vec<(usize, Clamp)>,
    /// Back stack elements in arrival order.
    back: Vec<(usize, Clamp)>,
    back_agg: Clamp,
}

impl ClampQueue {
    pub fn new() -> Self {
        Self {
            front: Vec::new(),
            back: Vec::new(),
            back_agg: Clamp::ID,
        }
    }
    #[inline(always)]
    pub fn push(&mut self, j: usize, f: Clamp) {
        self.back.push((j, f));
        self.back_agg = self.back_agg.then(f);
    }
    /// Drop every element with index < lo.
    pub fn expire(&mut self, lo: usize) {
        loop {
            if self.front.is_empty() {
                if self.back.first().is_none_or(|&(j, _)| j >= lo) {
                    return;
                }
                // Flip: move the back stack onto the front stack, newest first.
                let mut agg = Clamp::ID;
                while let Some((j, f)) = self.back.pop() {
                    agg = f.then(agg);
                    self.front.push((j, agg));
                }
                self.back_agg = Clamp::ID;
            }
            match self.front.last() {
                Some(&(j, _)) if j < lo => {
                    self.front.pop();
                }
                _ => return,
            }
        }
    }
    /// Composition of all queued maps, oldest outermost.
    #[inline(always)]
    pub fn aggregate(&self) -> Clamp {
        match self.front.last() {
            Some(&(_, f)) => f.then(self.back_agg),
            None => self.back_agg,
        }
    }
}

/// For each start k < `starts` with witness window `window(k)` = (first, end) (end exclusive, both
/// non-decreasing in k, asked in order of k): the largest over witnesses j in the window of min(ψ(j), min of φ(i) over
/// k + `from` ≤ i ≤ j − 1), −∞ for an empty window. O(starts + window ends) in all, as
/// [`super::eval`]'s until and the tube's lower bound: with s = max(first, k + from), min distributes over max, so the value is
/// min(min φ(k + from..s − 1), (f_s ∘ … ∘ f_{end−1})(−∞)) for the clamp maps f_j(y) = max(ψ(j),
/// min(φ(j), y)), plus ψ(k) when the window starts at k and the hold only after it (`from` = 1). Each
/// value is a selection among ψ's and φ's entries by min and max, so it is the one a scan of every
/// witness finds. φ past its end is never held (the last witness's map is applied to −∞).
pub(crate) fn windowed_until(
    psi: &[f64],
    phi: &[f64],
    from: usize,
    starts: usize,
    mut window: impl FnMut(usize) -> (usize, usize),
) -> Vec<f64> {
    let mut out = Vec::with_capacity(starts);
    // Sliding min of φ over k + from..s − 1, and the clamp maps of s..end.
    let (mut held, mut pushed_held) = (Wedge::new(), 0usize);
    let (mut maps, mut pushed_maps) = (ClampQueue::new(), 0usize);
    for k in 0..starts {
        let (first, end) = window(k);
        if first >= end {
            out.push(f64::NEG_INFINITY);
            continue;
        }
        let at_start = if first < k + from {
            psi[k]
        } else {
            f64::NEG_INFINITY
        };
        let s = first.max(k + from);
        let rest = if s < end {
            while pushed_held < s {
                held.push(phi, pushed_held, |x, y| x <= y);
                pushed_held += 1;
            }
            held.expire(k + from);
            let before = match held.front() {
                Some(i) if k + from < s => phi[i],
                _ => f64::INFINITY,
            };
            while pushed_maps < end {
                let beta = phi.get(pushed_maps).copied().unwrap_or(f64::INFINITY);
                maps.push(
                    pushed_maps,
                    Clamp {
                        alpha: psi[pushed_maps],
                        beta,
                    },
                );
                pushed_maps += 1;
            }
            maps.expire(s);
            before.min(maps.aggregate().alpha)
        } else {
            f64::NEG_INFINITY
        };
        out.push(at_start.max(rest));
    }
    out
}
