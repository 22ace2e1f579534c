//! The terminal law (section 11, optional, both modes): a certified linear law for after the task, with
//! the invariant ellipsoid it is certified on (issue 17, item 2).
//!
//! A reach-avoid task ends when the run enters Goal (Problem 2.26); the feedforward table and the PWA
//! envelope say nothing about afterwards. The host computes, where one exists, an equilibrium `x_e` in
//! Goal with its input `u_e` in the input set, a gain `K_t` and an ellipsoid
//! `E = {x : (x − x_e)ᵀ P_t (x − x_e) ≤ 1}` inside Goal and away from Unsafe, between samples too, that
//! the sampled loop `u = K_t x + v_t` (`v_t = u_e − K_t x_e`) maps strictly into itself with every input in
//! the input set, the evaluator's f32 rounding included. The section stores exactly what the evaluator
//! runs, as one raw body of little-endian `f32` (not postcard: a fixed layout decodes with one length
//! check, which keeps the firmware's decoder small), [`body_len`] bytes for n and m:
//!
//! | values | field |
//! |--------|-------|
//! | n      | the equilibrium `x_e` |
//! | m·n    | the gain `K_t`, row-major |
//! | m      | the offset `v_t = u_e − K_t x_e` |
//! | n·n    | the ellipsoid's `P_t`, row-major, symmetric positive definite |
//! | 1      | the acceptance radius `r̂ ≥ 0` |
//!
//! **Handover** (the evaluator's `Controller::step`, both modes): before the task's own law, the evaluator
//! tests `fl((x − x_e)ᵀ P_t (x − x_e)) ≤ r̂·r̂` with the same arithmetic as the feedforward ball selection,
//! so that the host's rounding analysis of that test (every accepted state lies in `E`) applies unchanged.
//! Accepted: `u = K_t x + v_t`, computed as the table law is, and the controller is in its terminal phase
//! from then on. In that phase a state the test refuses is outside what was certified (the certificate
//! maps `E` into the accepted set): the step answers out of envelope, for this step only.
//!
//! An image with model maps (a feedback-linearizable plant) carries no terminal law: the maps'
//! zero-dynamics bounds hold over [0, T] only.
#![allow(non_snake_case)]

use crate::capacity::{MAX_M, MAX_N};
use crate::error::{Field, ImageError, Pos};
use crate::linalg::{affine, quadratic_form};
use crate::raw::{check_finite, check_len, f32_at, floats, positive_definite, sat16};

/// Bytes of the section's body for state dimension n and input dimension m (module doc).
pub const fn body_len(n: usize, m: usize) -> usize {
    4 * (n + m * n + m + n * n + 1)
}

/// The `TerminalLaw` section's content (see the module doc), borrowed from its body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TerminalLaw<'a> {
    /// The equilibrium `x_e`, n values.
    pub x_e: &'a [u8],
    /// The gain `K_t`, m×n row-major.
    pub K: &'a [u8],
    /// The offset `v_t = u_e − K_t x_e`, m values.
    pub v: &'a [u8],
    /// The ellipsoid's matrix `P_t`, n×n, symmetric positive definite.
    pub P: &'a [u8],
    /// The acceptance radius `r̂ ≥ 0` of the handover test.
    pub radius: f32,
}

impl<'a> TerminalLaw<'a> {
    /// The law a section body holds (module doc), validated ([`TerminalLaw::validate`]); a body of
    /// another length is refused with [`ImageError::FieldLength`].
    pub fn decode(body: &'a [u8], n: usize, m: usize) -> Result<Self, ImageError> {
        let (n, m) = (n.clamp(1, MAX_N), m.clamp(1, MAX_M));
        check_len(Field::TerminalLaw, body, body_len(n, m))?;
        let (x_e, rest) = body.split_at_checked(4 * n).unwrap_or((&[], &[]));
        let (K, rest) = rest.split_at_checked(4 * m * n).unwrap_or((&[], &[]));
        let (v, rest) = rest.split_at_checked(4 * m).unwrap_or((&[], &[]));
        let (P, rest) = rest.split_at_checked(4 * n * n).unwrap_or((&[], &[]));
        let law = TerminalLaw {
            x_e,
            K,
            v,
            P,
            radius: f32_at(rest, 0),
        };
        law.validate(n, m)?;
        Ok(law)
    }

    /// Checks the lengths against n and m, every float finite, `P_t` exactly symmetric and positive
    /// definite, and `r̂ ≥ 0`.
    pub fn validate(&self, n: usize, m: usize) -> Result<(), ImageError> {
        let (n, m) = (n.clamp(1, MAX_N), m.clamp(1, MAX_M));
        for (field, bytes, len) in [
            (Field::TerminalCentre, self.x_e, n),
            (Field::TerminalK, self.K, m * n),
            (Field::TerminalV, self.v, m),
            (Field::TerminalP, self.P, n * n),
        ] {
            check_len(field, bytes, 4 * len)?;
            check_finite(field, bytes, flat)?;
        }
        for r in 0..n {
            for c in (r + 1)..n {
                if f32_at(self.P, r * n + c).to_bits() != f32_at(self.P, c * n + r).to_bits() {
                    return Err(ImageError::BadTerminalLaw);
                }
            }
        }
        if !positive_definite(self.P, n) || !self.radius.is_finite() || self.radius < 0.0 {
            return Err(ImageError::BadTerminalLaw);
        }
        Ok(())
    }

    /// The handover test: `fl((x − x_e)ᵀ P_t (x − x_e)) ≤ r̂·r̂`, summed as the feedforward selection sums
    /// ([`crate::linalg::quadratic_form`]). `x` has n values (validated by the caller).
    #[inline(always)]
    pub fn accepts(&self, x: &[f32], n: usize) -> bool {
        let mut e = [0.0f32; MAX_N];
        for ((ei, &xi), ci) in e.iter_mut().zip(x).zip(floats(self.x_e)) {
            *ei = xi - ci;
        }
        quadratic_form(self.P, &e, n.clamp(1, MAX_N)) <= self.radius * self.radius
    }

    /// `u_j = (K_t x)_j + v_t,j` into `u[..m]`, summed as the table law `u = K_ℓ x + v` is
    /// ([`crate::linalg::affine`]).
    #[inline(always)]
    pub fn law(&self, x: &[f32], n: usize, m: usize, u: &mut [f32; MAX_M]) {
        affine(self.K, x, self.v, n.clamp(1, MAX_N), m.clamp(1, MAX_M), u);
    }
}

/// Position of entry i of a flat array (one function for every field, so that `check_finite` is
/// instantiated once here).
fn flat(i: usize) -> Pos {
    Pos(sat16(i), 0, 0)
}
