//! Sine and cosine in f32 arithmetic only, for model programs (a rotation by a measured angle: the
//! offset-thruster vehicle of Example 4.9, the pendulum, the quadrotor's thrust angle of Example 4.10).
//!
//! Why not `libm::sincosf`: its kernels evaluate in f64, which the Cortex-M4F's single-precision FPU
//! emulates in software (about 2 300 instructions per call, more than the rest of a quadrotor step); a
//! crate of f32-only approximations such as `micromath` is far coarser than the few-ulp accuracy the
//! rounding analysis assumes. So this is the classic construction in f32: Cody–Waite reduction by π/2
//! (three constants whose leading parts multiply an integer exactly) and Cephes' minimax polynomials on
//! [−π/4, π/4], about 40 instructions. Every operation is a plain IEEE binary32 `+ − ·` or an integer
//! conversion, with no fused multiply-add, so host and target (and the C export, which ports it) give
//! the same bits.
//!
//! Accuracy: for |x| ≤ [`REDUCED_MAX`], per component
//! |sincos(x) − (sin x, cos x)| ≤ U·2⁻²³·|value| + U·2⁻¹⁴⁹ + [`REDUCTION_ABS`]·(|x| + 2) with U = 2.
//! The last term is the reduction's: k·C3 is rounded (and π/2 − (C1 + C2 + C3) is not 0), an absolute
//! error that matters only near a zero of sin or cos, where the value itself is tiny. The tests check the
//! bound on sampled f32 and next to every multiple of π/2 in range; an exhaustive run over every
//! positive f32 up to the limit is in `tests` (ignored by default: 40 s in release), whose worst case is
//! U = 1.03 (at x = 7101.045). The program rounding analysis (`host_compiler::expr::interval`) charges
//! 4 ulps and this absolute term. Beyond the limit, NaN and ±∞ the answer is `libm::sincosf`'s.

/// The largest |x| reduced here: |k| ≤ 2¹³ keeps k·[`C1`] and k·[`C2`] exact (8 and 11 significant bits).
pub const REDUCED_MAX: f32 = 8192.0;

/// The reduction's absolute error per unit of |x| + 2 (module doc): |k| ≤ 0.64|x| + 1 times
/// |C3|·2⁻²⁴ + |π/2 − (C1 + C2 + C3)| ≤ 6.2·10⁻¹⁵, with a margin.
pub const REDUCTION_ABS: f64 = 1.0e-14;

/// 2/π rounded to f32.
const FRAC_2_PI: f32 = core::f32::consts::FRAC_2_PI;
/// π/2 = C1 + C2 + C3 (+ 4·10⁻¹⁵): C1 has 8 significant bits, C2 11, C3 is the rest rounded.
const C1: f32 = 1.5703125;
const C2: f32 = 4.837_513e-4;
const C3: f32 = 7.549_79e-8;

/// Cephes `sinf`: sin r ≈ r + r³(S1 + r²(S2 + r²S3)) on |r| ≤ π/4.
const S1: f32 = -1.666_665_5e-1;
const S2: f32 = 8.332_161e-3;
const S3: f32 = -1.951_529_6e-4;
/// Cephes `cosf`: cos r ≈ 1 − r²/2 + r⁴(K1 + r²(K2 + r²K3)) on |r| ≤ π/4.
const K1: f32 = 4.166_664_6e-2;
const K2: f32 = -1.388_731_6e-3;
const K3: f32 = 2.443_315_7e-5;

/// `(sin x, cos x)` in f32 (module doc). Odd and even exactly: sin(−x) = −sin x, cos(−x) = cos x.
#[inline]
pub fn sincos(x: f32) -> (f32, f32) {
    let a = libm::fabsf(x);
    if a.is_nan() || a > REDUCED_MAX {
        return libm::sincosf(x);
    }
    // k = round(a·2/π) (half up; a ≥ 0), so |r| ≤ π/4 up to the rounding of a·2/π.
    let k = (a * FRAC_2_PI + 0.5) as i32;
    let kf = k as f32;
    let r = ((a - kf * C1) - kf * C2) - kf * C3;
    let z = r * r;
    let s = r + ((S3 * z + S2) * z + S1) * z * r;
    let c = (((K3 * z + K2) * z + K1) * z * z - 0.5 * z) + 1.0;
    let (sa, ca) = match k & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    };
    (if x.is_sign_negative() { -sa } else { sa }, ca)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The error of `got` against the f64 value `exact` at `x`, less the reduction's absolute term, in
    /// units of 2⁻²³·|exact| + 2⁻¹⁴⁹ (the bound of the module doc, with U the answer).
    fn ulps(got: f32, exact: f64, x: f32) -> f64 {
        let abs = REDUCTION_ABS * (x.abs() as f64 + 2.0);
        ((got as f64 - exact).abs() - abs).max(0.0)
            / (exact.abs() * 2f64.powi(-23) + 2f64.powi(-149))
    }

    fn worst(x: f32) -> f64 {
        let (s, c) = sincos(x);
        let xd = x as f64;
        ulps(s, xd.sin(), x).max(ulps(c, xd.cos(), x))
    }

    /// Every positive f32 up to [`REDUCED_MAX`] (odd and even exactly, so that covers the range):
    /// `cargo test -p shared-types --release -- --ignored every_f32`.
    #[test]
    #[ignore = "40 s in release: every f32 in range"]
    fn every_f32_in_range_is_within_two_ulps() {
        let mut max = (0.0f64, 0.0f32);
        for b in 0..=REDUCED_MAX.to_bits() {
            let x = f32::from_bits(b);
            let w = worst(x);
            if w > max.0 {
                max = (w, x);
            }
        }
        assert!(max.0 <= 2.0, "worst {} ulps at {:e}", max.0, max.1);
    }

    #[test]
    fn sine_and_cosine_are_within_two_ulps_over_the_reduced_range() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let mut max = 0.0f64;
        // Uniform in value (most of the range) and uniform in bits (the small arguments).
        for _ in 0..200_000 {
            let x: f32 = rng.random_range(-REDUCED_MAX..=REDUCED_MAX);
            max = max.max(worst(x));
            let b = rng.random_range(0..=REDUCED_MAX.to_bits());
            max = max.max(worst(f32::from_bits(b)));
        }
        // The f32 neighbours of multiples of π/2 (zeros of one of the two, where relative error is hard).
        for k in -5000i32..=5000 {
            let m = (k as f64 * core::f64::consts::FRAC_PI_2) as f32;
            let mut x = f32::from_bits(m.to_bits().saturating_sub(3));
            for _ in 0..7 {
                if x.abs() <= REDUCED_MAX {
                    max = max.max(worst(x));
                }
                x = f32::from_bits(x.to_bits() + 1);
            }
        }
        assert!(max <= 2.0, "worst error {max} ulps");
    }

    #[test]
    fn beyond_the_range_and_at_special_values_it_is_libm() {
        for x in [8192.5f32, -1.0e6, 3.0e38, f32::INFINITY, f32::NEG_INFINITY] {
            let (s, c) = sincos(x);
            let (ls, lc) = libm::sincosf(x);
            assert_eq!(
                (s.to_bits(), c.to_bits()),
                (ls.to_bits(), lc.to_bits()),
                "x = {x}"
            );
        }
        let (s, c) = sincos(f32::NAN);
        assert!(s.is_nan() && c.is_nan());
        assert_eq!(sincos(0.0), (0.0, 1.0));
        assert_eq!(sincos(-0.0).0.to_bits(), (-0.0f32).to_bits());
    }

    #[test]
    fn sine_is_odd_and_cosine_even_to_the_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for _ in 0..10_000 {
            let x: f32 = rng.random_range(-100.0..100.0);
            let (s, c) = sincos(x);
            let (sn, cn) = sincos(-x);
            assert_eq!((s.to_bits(), c.to_bits()), ((-sn).to_bits(), cn.to_bits()));
        }
    }
}
