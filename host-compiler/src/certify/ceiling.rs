//! The largest radius any nominal of a given length can be certified with by a loop, from the parts of
//! Theorem 4.7 (and Theorem 4.2 for an MTL task) that do not depend on the nominal: the input part (4.15),
//! r_crit (3.83) and, for a plant with a sampled-loop mismatch D, the disturbance the table accumulates.
//! When it is below the admission floor δε, no search for nominal trajectories can find one to admit, and
//! the cover's growth says so at once, with these figures, instead of trying seeds for its whole budget.
//!
//! # Why it bounds every certificate
//! [`super::certify_at`] and [`super::temporal`] take d = min(parts) ≤ δ_Input, where δ_Input is the least
//! over the table's steps of the input's scaled slack ([`super::input_distance_scaled`]):
//! * a box: min_i min(hi_i − ε_i − u_i, u_i − lo_i − ε_i)/s_i ≤ min_i ((hi_i − lo_i)/2)/s_i, its largest
//!   value over every u and every rounding ε ≥ 0 (a component with s_i = 0 bounds nothing);
//! * a Euclidean ball: (max − ‖ε‖ − ‖u − c‖)/s ≤ max/s.
//!
//! That bound is [`Ceiling::input`]. The certificate's δ is then d(1 − 10⁻⁹) if r_crit(ε̄) < d, else 0, and,
//! with a mismatch step z = φβD (+ a flat plant's state step) > 0, at most max(that, d − S_N·(‖P½B‖ε̄ + z)),
//! S_N = Σ_{j<N} ‖Ã^j‖_P. Every term of r_crit (3.82)–(3.87) is non-decreasing in ε̄, so r_crit(ε̄) ≥
//! r_crit(0) = [`Ceiling::r_crit`]; and S_N(‖P½B‖ε̄ + z) ≥ S_N z = [`Ceiling::accumulated`]. Hence every δ
//! is at most
//!   [`Ceiling::value`] = max(input if r_crit(0) < input else 0, input − S_N z if z > 0 else 0),
//! and S_N grows with N, so a longer table is bounded by it too.

use super::{InputScale, Loop, LoopConstants};
use crate::property::InputBound;

/// The bound of the module doc for one loop and a table of `steps` samples.
#[derive(Clone, Debug, PartialEq)]
pub struct Ceiling {
    /// The largest input part (4.15) any nominal can have.
    pub input: f64,
    /// r_crit without rounding (it only grows with the rounding).
    pub r_crit: f64,
    /// S_N·z: the mismatch alone accumulated over the table; 0 for a plant without one.
    pub accumulated: f64,
    /// The table's length N in samples.
    pub steps: usize,
    /// No certificate of a table of at least `steps` samples has a larger δ.
    pub value: f64,
}

impl Ceiling {
    /// The ceiling of the loop `lp` with its constants `lc` for tables of `steps` samples.
    pub fn of(lp: &Loop<'_>, lc: &LoopConstants, steps: usize) -> Self {
        let scale = InputScale::new(lp.K, &lc.roots, lp.input());
        let over = |half: f64, s: f64| if s > 0.0 { half / s } else { f64::INFINITY };
        let input = match (lp.input(), &scale) {
            (InputBound::Box { lo, hi }, InputScale::Rows(rows)) => rows
                .iter()
                .enumerate()
                .map(|(i, &s)| over(0.5 * (hi[i] - lo[i]), s))
                .fold(f64::INFINITY, f64::min),
            (InputBound::Norm2 { max, .. }, InputScale::Norm(s)) => over(*max, *s),
            // `InputScale::new` builds the scale of the input set's own kind.
            _ => f64::INFINITY,
        };
        let r_crit = lc.r_crit(0.0);
        let z = lc.mismatch_step();
        let accumulated = if z > 0.0 {
            lc.accumulation(steps) * z
        } else {
            0.0
        };
        let by_r_crit = if r_crit < input { input } else { 0.0 };
        let by_sum = if z > 0.0 { input - accumulated } else { 0.0 };
        Self {
            input,
            r_crit,
            accumulated,
            steps,
            value: by_r_crit.max(by_sum).max(0.0),
        }
    }

    /// True when no certificate can reach the admission floor `floor` (δ must also be positive).
    pub fn below(&self, floor: f64) -> bool {
        !(self.value > 0.0 && self.value >= floor)
    }
}

impl std::fmt::Display for Ceiling {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "no nominal input keeps more than {:.3e} of input margin (the input set's half-width over \
             the gain's scale in the CAF metric, (4.15))",
            self.input
        )?;
        if self.accumulated > 0.0 {
            write!(
                f,
                ", while the sampled-loop mismatch alone moves a run up to {:.3e} over a table of {} \
                 samples (S_N·φβD)",
                self.accumulated, self.steps
            )?;
        }
        write!(
            f,
            " and r_crit without rounding is {:.3e}; so no trajectory's certified δ exceeds {:.3e}",
            self.r_crit, self.value
        )
    }
}
