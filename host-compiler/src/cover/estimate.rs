//! Coverage of Init by certified balls (§2.5.2): uniform sampling of a box, the unbiased coverage estimate,
//! and its one-sided Chernoff bounds at a stated confidence.
//!
//! With N independent uniform samples of Init and the indicator D_j of "sample j is covered", the mean
//! D̄ = (1/N) Σ D_j is unbiased for the covered volume fraction p, and (§2.5.2)
//!
//! * P[p ≤ D̄ − ε] ≤ exp(−ε² N / (2 + ε))   (lower tail),
//! * P[p ≥ D̄ + ε] ≤ exp(−ε² N / 2)         (upper tail).
//!
//! Setting the right-hand side to 1 − confidence and solving for ε gives the bounds reported here.

use rand::Rng;

/// Half-width ε of the lower one-sided Chernoff bound: the ε solving exp(−ε²N/(2+ε)) = 1 − confidence.
///
/// With L = ln(1/(1−c)), ε² N − L ε − 2 L = 0, so ε = (L + sqrt(L² + 8 N L)) / (2N).
pub fn chernoff_lower_eps(n: usize, confidence: f64) -> f64 {
    let L = -(1.0 - confidence).ln();
    let N = n as f64;
    (L + (L * L + 8.0 * N * L).sqrt()) / (2.0 * N)
}

/// Half-width ε of the upper one-sided Chernoff bound: exp(−ε²N/2) = 1 − confidence.
pub fn chernoff_upper_eps(n: usize, confidence: f64) -> f64 {
    let L = -(1.0 - confidence).ln();
    (2.0 * L / n as f64).sqrt()
}

/// The number of samples for which a sample with every point covered proves coverage ≥ `target` at
/// `confidence` (the smallest N with 1 − ε_lower(N) ≥ target).
pub fn samples_needed(target: f64, confidence: f64) -> usize {
    let eps = 1.0 - target;
    if eps <= 0.0 {
        return usize::MAX;
    }
    let L = -(1.0 - confidence).ln();
    // ε²N ≥ L(2+ε)  ⇔  N ≥ L(2+ε)/ε².
    let n = (L * (2.0 + eps) / (eps * eps)).ceil() as usize;
    // Guard against rounding at the boundary.
    let mut n = n.max(1);
    while 1.0 - chernoff_lower_eps(n, confidence) < target {
        n += 1;
    }
    n
}

/// The fresh samples of a final coverage estimate: enough that a fully covered sample proves the spec's
/// coverage target at its confidence, and at least the spec's tolerance asks for. A target of 1 asks for
/// no more than the tolerance: a finite sample never proves 100 %.
pub fn final_samples(s: &crate::spec::SynthesisSettings) -> usize {
    s.coverage_samples().max(if s.coverage_target < 1.0 {
        samples_needed(s.coverage_target, s.confidence)
    } else {
        0
    })
}

/// A coverage estimate with its Chernoff bounds.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CoverageEstimate {
    /// Number of uniform samples drawn.
    pub samples: usize,
    /// How many were covered.
    pub covered: usize,
    /// Unbiased estimate D̄.
    pub mean: f64,
    /// Confidence of each one-sided bound.
    pub confidence: f64,
    /// Lower bound D̄ − ε_lower (clamped at 0): P[p ≤ lower] ≤ 1 − confidence.
    pub lower: f64,
    /// Upper bound D̄ + ε_upper (clamped at 1): P[p ≥ upper] ≤ 1 − confidence.
    pub upper: f64,
}

impl CoverageEstimate {
    /// Bounds from a count.
    pub fn from_counts(samples: usize, covered: usize, confidence: f64) -> Self {
        let mean = if samples == 0 {
            0.0
        } else {
            covered as f64 / samples as f64
        };
        let (lower, upper) = if samples == 0 {
            (0.0, 1.0)
        } else {
            (
                (mean - chernoff_lower_eps(samples, confidence)).max(0.0),
                (mean + chernoff_upper_eps(samples, confidence)).min(1.0),
            )
        };
        Self {
            samples,
            covered,
            mean,
            confidence,
            lower,
            upper,
        }
    }
}

/// An axis-aligned box [lo, hi] (coordinates with lo = hi are pinned).
#[derive(Clone, Debug, PartialEq)]
pub struct SampleBox {
    pub lo: Vec<f64>,
    pub hi: Vec<f64>,
}

impl SampleBox {
    /// A uniform sample of the box (pinned coordinates are copied).
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> Vec<f64> {
        self.lo
            .iter()
            .zip(&self.hi)
            .map(|(&l, &h)| if h > l { rng.random_range(l..=h) } else { l })
            .collect()
    }

    /// Draw `n` uniform samples.
    pub fn samples<R: Rng + ?Sized>(&self, n: usize, rng: &mut R) -> Vec<Vec<f64>> {
        (0..n).map(|_| self.sample(rng)).collect()
    }
}

/// Estimate the covered fraction of `init` from `n` fresh uniform samples.
pub fn estimate<R: Rng + ?Sized>(
    init: &SampleBox,
    n: usize,
    confidence: f64,
    rng: &mut R,
    covered: impl Fn(&[f64]) -> bool,
) -> CoverageEstimate {
    let mut count = 0;
    for _ in 0..n {
        let x = init.sample(rng);
        if covered(&x) {
            count += 1;
        }
    }
    CoverageEstimate::from_counts(n, count, confidence)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn eps_solves_the_chernoff_equation() {
        for &(n, c) in &[(100usize, 0.9), (10_000, 0.99), (92_000, 0.99), (5, 0.5)] {
            let e = chernoff_lower_eps(n, c);
            let lhs = (-e * e * n as f64 / (2.0 + e)).exp();
            assert!((lhs - (1.0 - c)).abs() < 1e-12, "n={n} c={c}: {lhs}");
            let e = chernoff_upper_eps(n, c);
            let lhs = (-e * e * n as f64 / 2.0).exp();
            assert!((lhs - (1.0 - c)).abs() < 1e-12);
        }
    }

    #[test]
    fn samples_needed_is_the_smallest_sufficient_count() {
        let n = samples_needed(0.99, 0.99);
        assert!(1.0 - chernoff_lower_eps(n, 0.99) >= 0.99);
        assert!(1.0 - chernoff_lower_eps(n - 1, 0.99) < 0.99);
        // ln(100)·2.01/1e-4 ≈ 92 565.
        assert!((92_000..93_000).contains(&n), "{n}");
    }

    /// The lower bound must fail (p ≤ lower) in at most a (1 − confidence) share of repeated experiments.
    #[test]
    fn lower_bound_holds_at_its_confidence() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let bx = SampleBox {
            lo: vec![0.0, 0.0],
            hi: vec![1.0, 1.0],
        };
        let p = 0.3; // covered: x0 < 0.3
        let trials = 400;
        let mut failures = 0;
        for _ in 0..trials {
            let est = estimate(&bx, 200, 0.9, &mut rng, |x| x[0] < p);
            if p <= est.lower {
                failures += 1;
            }
            assert!(est.lower <= est.mean && est.mean <= est.upper);
        }
        // Expected at most 10 % (Chernoff is conservative, so far fewer in practice).
        assert!(failures <= trials / 10, "{failures} failures of {trials}");
    }

    #[test]
    fn pinned_coordinates_are_kept() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let bx = SampleBox {
            lo: vec![-0.2, 0.0, 1.0],
            hi: vec![0.2, 0.0, 1.0],
        };
        for _ in 0..100 {
            let x = bx.sample(&mut rng);
            assert!((-0.2..=0.2).contains(&x[0]));
            assert_eq!(x[1], 0.0);
            assert_eq!(x[2], 1.0);
        }
    }
}
