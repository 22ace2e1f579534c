//! The image's coverage of the *spec's* Init, estimated by `verify` as `synth` estimates a cover's
//! (§2.5.2, [`crate::cover::estimate`]): uniform samples of Init, each counted when the image's own f32
//! selection accepts it and the ball it selects was re-proved from the bytes. A spec fingerprint only
//! says which spec an image was made for; this estimate says how much of that spec's Init the image
//! certifies (issue 42, item 2). For a feedback-linearizable or flat plant the samples are plant states,
//! taken to ξ by the image's coords program in f32 with the controller's states at ζ0 (as the evaluator
//! does at κ = 0); for a hybrid image they lie in the initial location; for a PWA image a sample counts
//! when the image's point location puts it inside a certified ball.
//!
//! The number of samples is the one `synth`'s final estimate draws ([`crate::cover::estimate::final_samples`]),
//! the bounds are its one-sided Chernoff bounds at the spec's confidence, and the draw is seeded, so the
//! figure is deterministic and independent of the thread count (the samples are drawn in order, then
//! judged in parallel).

use crate::cover::estimate::{final_samples, CoverageEstimate, SampleBox};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use shared_types::eval::Controller;
use shared_types::image::{Image, Mode};
use shared_types::program::Workspace;

/// The estimate and the spec's target.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Coverage {
    #[serde(flatten)]
    pub estimate: CoverageEstimate,
    /// The spec's `coverage_target`.
    pub target: f64,
    /// Whether the lower bound reaches the target (else `verify` exits 3).
    pub met: bool,
}

/// Which stored balls were re-proved (index = trajectory); a sample selecting another counts as
/// uncovered. Empty: every ball (a PWA image, whose re-proof is over its partitions).
pub type Proved<'a> = &'a [bool];

/// Whether the image covers the point `x` of Init (module doc).
pub fn covers(image: &Image<'_>, proved: Proved<'_>, x: &[f64]) -> bool {
    let ctl = Controller::new(*image);
    let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
    if image.mode() == Mode::PwaFeedback {
        return matches!(
            ctl.locate(&x32),
            Some(shared_types::pwa::Region::Inside { .. })
        );
    }
    let selected = match image.model_maps() {
        None => ctl.select(&x32),
        Some(mm) => {
            let (np, ne) = (mm.n_plant(), mm.n_ext());
            if x32.len() != np {
                return false;
            }
            let inputs: Vec<f32> = x32.iter().copied().chain(mm.ext_inits()).collect();
            let mut xi = vec![0.0f32; image.n()];
            let mut work = Workspace::new();
            if inputs.len() != np + ne
                || mm.coords().eval_with(&inputs, &mut xi, &mut work).is_err()
                || !xi.iter().all(|v| v.is_finite())
            {
                return false;
            }
            ctl.select_maps(&xi)
        }
    };
    selected.is_some_and(|t| proved.is_empty() || proved.get(t as usize) == Some(&true))
}

/// The coverage of `init` by `image` (module doc), with `settings`' sample count, confidence and target.
pub fn estimate(
    image: &Image<'_>,
    proved: Proved<'_>,
    init: &SampleBox,
    settings: &crate::spec::SynthesisSettings,
    seed: u64,
) -> Coverage {
    let n = final_samples(settings);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let samples = init.samples(n, &mut rng);
    let covered = samples
        .par_iter()
        .filter(|x| covers(image, proved, x))
        .count();
    let estimate = CoverageEstimate::from_counts(n, covered, settings.confidence);
    Coverage {
        met: estimate.lower >= settings.coverage_target,
        target: settings.coverage_target,
        estimate,
    }
}

/// The seed of the coverage draw from the spec's (or `--seed`): a stream of its own, apart from the
/// Monte Carlo's.
pub fn seed_of(seed: u64) -> u64 {
    seed ^ 0xc0_5e_a9e
}
