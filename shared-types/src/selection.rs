//! The selection test section (kind [`crate::layout::SectionKind::SelectionTest`], tag 13; optional, only
//! in a feedforward image with model maps): the ball test the model-maps step selects a trajectory with
//! at κ = 0 (Algorithm 2, step 2), in the whitened form of the PWA ball test ([`crate::pwa`], "The
//! whitened ball test", whose rounding analysis applies here unchanged).
//!
//! Why a second test: Algorithm 2 tests every ball at κ = 0, and `(x − c)ᵀP(x − c)` costs n² + n
//! multiply-adds per ball. The flat quadrotor of Example 4.10 has n = 8 and a cover of a dozen balls,
//! so its first step was dominated by the selection. With the factor `P_ℓ = R_ℓᵀR_ℓ`, `z = fl(R̂_ℓ x̂)` is
//! formed once (n(n+1)/2 multiply-adds) and each ball costs n subtractions and n multiply-adds.
//!
//! # Byte layout (raw, little-endian f32)
//! | values | content |
//! |---|---|
//! | `n_locations × n × n` | per location ℓ, `R̂_ℓ = fl32(R_ℓ)`, row-major, exactly 0 below the diagonal, positive diagonal |
//! | `n_trajectories × (n + 1)` | per trajectory i, its test record `[ĉ_z,0 … ĉ_z,n−1, ŝ]`: `ĉ_z = fl32(R̂_ℓ ĉ)` (ĉ the stored centre, ℓ the location of the trajectory's first segment) and the squared threshold `ŝ ≥ 0` |
//!
//! # The test
//! For the measured ξ (n finite values), `z = fl(R̂_ℓ ξ)` (row i: `Σ_{j=i}^{n−1} R̂_ij ξ_j` left to right
//! from 0) and, per trajectory, `s_i = fl(Σ_k fl(z_k − ĉ_z,k)²)` summed left to right from 0. The
//! selected trajectory is the one with the least `s_i` among those with `s_i ≤ ŝ_i`, ties to the lowest
//! index; none → out of the envelope, as for the P-metric test. The host stores `ŝ_i` so that every
//! accepted state lies in the trajectory's certified ball
//! (`host_compiler::certify::pwa_ball_threshold`, the bound in [`crate::pwa`]), and the verifier re-proves
//! that from these bytes (`host_compiler::certify::pwa_accept_radius`).
//!
//! The P-metric test ([`crate::eval::Controller::select`]) stays what [`crate::eval::Controller::step`]
//! runs; the model-maps step ([`crate::eval::Controller::step_plant`]) runs this one when the image has
//! the section. Both are certified for every ball, so each picks a certified trajectory; they may differ
//! only near a ball's boundary or between two balls at nearly equal distance.
#![allow(non_snake_case)]

use crate::capacity::{MAX_N, MAX_TRAJECTORIES};
use crate::error::{Field, ImageError};
use crate::layout::Dims;
use crate::pwa::{load_ball, validate_ball_tests, validate_factors, whiten};
use crate::raw::{check_len, f32_at, floats};

/// The decoded section: the factors and the test records, borrowed from the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SelectionTest<'a> {
    R: &'a [u8],
    tests: &'a [u8],
    body: &'a [u8],
}

/// Bytes of the section body for state dimension n, `n_locations` locations and `n_trajectories`
/// trajectories.
pub const fn body_len(n: usize, n_locations: usize, n_trajectories: usize) -> usize {
    4 * (n_locations * n * n + n_trajectories * (n + 1))
}

impl<'a> SelectionTest<'a> {
    /// Validates `body` against the image's dimensions (module doc): its length, every value finite,
    /// each factor upper triangular with a positive diagonal, every threshold ≥ 0.
    pub fn decode(
        body: &'a [u8],
        n: usize,
        n_locations: usize,
        n_trajectories: usize,
    ) -> Result<Self, ImageError> {
        let n = n.clamp(1, MAX_N);
        check_len(
            Field::SelectionTest,
            body,
            body_len(n, n_locations, n_trajectories),
        )?;
        let (R, tests) = body
            .split_at_checked(4 * n_locations * n * n)
            .unwrap_or((&[], &[]));
        validate_factors(R, n_locations, n)?;
        validate_ball_tests(tests, n_trajectories, n)?;
        Ok(SelectionTest { R, tests, body })
    }

    /// The section's bytes.
    pub fn body(&self) -> &'a [u8] {
        self.body
    }

    /// `R̂_ℓ[row][col]` (0 out of range).
    pub fn factor(&self, n: usize, location: usize, row: usize, col: usize) -> f32 {
        f32_at(self.R, (location * n + row) * n + col)
    }

    /// Component i of trajectory t's whitened centre `ĉ_z` (0 out of range).
    pub fn centre_z(&self, n: usize, t: usize, i: usize) -> f32 {
        f32_at(self.tests, t * (n + 1) + i)
    }

    /// Trajectory t's squared threshold ŝ (0 out of range).
    pub fn threshold(&self, n: usize, t: usize) -> f32 {
        f32_at(self.tests, t * (n + 1) + n)
    }

    /// The selection of the module doc for the state `x` of the image of dimensions `dims` whose section
    /// this is, `first_location(t)` the location of trajectory t's first segment; `None` if no ball
    /// accepts `x` or `x` has the wrong length. A one-location image of dimension 8 (the flat
    /// quadrotor) or 4 (the planar vehicles) runs an unrolled instance, every other image the general
    /// loop: the same operations in the same order, so the same answer.
    pub(crate) fn select(
        &self,
        dims: Dims,
        first_location: impl Fn(usize) -> usize,
        x: &[f32],
    ) -> Option<u16> {
        let n = dims.n.clamp(1, MAX_N);
        if x.len() != n {
            return None;
        }
        let count = dims.n_trajectories.min(MAX_TRAJECTORIES);
        if dims.n_locations == 1 {
            match n {
                8 => return self.select_fixed::<8>(x, count),
                4 => return self.select_fixed::<4>(x, count),
                _ => {}
            }
        }
        let mut z = [0.0f32; MAX_N];
        let mut z_loc = usize::MAX;
        let mut best: Option<u16> = None;
        let mut best_s = f32::INFINITY;
        for t in 0..count {
            let l = if dims.n_locations == 1 {
                0
            } else {
                first_location(t)
            };
            if l != z_loc {
                for (i, zi) in z.iter_mut().enumerate().take(n) {
                    let mut s = 0.0f32;
                    for (j, &xj) in x.iter().enumerate().skip(i) {
                        s += self.factor(n, l, i, j) * xj;
                    }
                    *zi = s;
                }
                z_loc = l;
            }
            // The record, read with one bounds check (never short for a validated section).
            let Some(rec) = self.tests.get(4 * t * (n + 1)..4 * (t + 1) * (n + 1)) else {
                break;
            };
            let mut s = 0.0f32;
            for (&zk, c) in z.iter().take(n).zip(floats(rec)) {
                let d = zk - c;
                s += d * d;
            }
            if s <= f32_at(rec, n) && s < best_s {
                best_s = s;
                best = Some(t as u16);
            }
        }
        best
    }

    /// [`SelectionTest::select`] for one location and dimension N, unrolled: `z` once, then one
    /// contiguous read per test record.
    #[inline(never)]
    fn select_fixed<const N: usize>(&self, x: &[f32], count: usize) -> Option<u16> {
        let mut xa = [0.0f32; N];
        xa.copy_from_slice(x.get(..N)?);
        let mut z = [0.0f32; N];
        whiten::<N>(&mut z, self.R, 0, &xa);
        let mut best: Option<u16> = None;
        let mut best_s = f32::INFINITY;
        for t in 0..count {
            let Some((cz, threshold)) = load_ball::<N>(self.tests, t) else {
                break;
            };
            let mut s = 0.0f32;
            for k in 0..N {
                let d = z[k] - cz[k];
                s += d * d;
            }
            if s <= threshold && s < best_s {
                best_s = s;
                best = Some(t as u16);
            }
        }
        best
    }
}
