//! Why examples/planar-vehicle-pwa-4.toml samples at 0.06 s: Example 6.4 states σ_min(P − ÃᵀPÃ) > 0.1 for the
//! P and K it prints, and that holds for the planar vehicle's exact zero-order-hold loop only when the sample
//! period is at least about 0.058 s. Ã = e^{(A + BK)h} is computed with the crate's `expm`; per axis the
//! state is (position, velocity), P = [7.03 5.17; 5.17 6.85] (the printed off-diagonal sign, −5.17, makes
//! P − ÃᵀPÃ indefinite for every h, checked below too), K = −[2.34 3.38].

#![allow(non_snake_case)]

use faer::Mat;
use host_compiler::linalg::{sym, sym_eigenvalues};
use host_compiler::model::expm;

/// σ_min(P − ÃᵀPÃ) for one axis of the planar vehicle (ẍ = −x + 0.1ẋ + u) with u = −k_p x − k_v ẋ.
fn sigma_min(p12: f64, h: f64) -> f64 {
    let (kp, kv) = (2.34, 3.38);
    let Acl = Mat::from_fn(2, 2, |i, j| [[0.0, 1.0], [-1.0 - kp, 0.1 - kv]][i][j] * h);
    let At = expm(Acl.as_ref()).expect("expm");
    let P = Mat::from_fn(2, 2, |i, j| [[7.03, p12], [p12, 6.85]][i][j]);
    let M = &P - At.transpose() * &P * &At;
    sym_eigenvalues(sym(M.as_ref()).as_ref()).expect("eigenvalues")[0]
}

#[test]
fn the_texts_margin_needs_a_period_of_at_least_0_058_s() {
    // The figures quoted in the example's comment.
    assert!((sigma_min(5.17, 0.01) - 0.0175).abs() < 5e-4);
    assert!((sigma_min(5.17, 0.05) - 0.086).abs() < 1e-3);
    assert!((sigma_min(5.17, 0.06) - 0.103).abs() < 1e-3);
    // The crossing of 0.1 lies between 0.057 and 0.059 s, and the period the example uses clears it.
    assert!(sigma_min(5.17, 0.057) < 0.1);
    assert!(sigma_min(5.17, 0.059) > 0.1);
    let spec = host_compiler::spec::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle-pwa-4.toml"
    ))
    .expect("the example parses");
    assert!(sigma_min(5.17, spec.plant.period) > 0.1);
    // The PWA law over the whole of Init samples at a longer period, where the margin holds too.
    let full = host_compiler::spec::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle-pwa.toml"
    ))
    .expect("the example parses");
    assert!(full.plant.period > spec.plant.period && sigma_min(5.17, full.plant.period) > 0.1);
    // With the printed sign the matrix is indefinite at any period.
    for h in [0.01, 0.06, 0.1] {
        assert!(sigma_min(-5.17, h) < 0.0, "h = {h}");
    }
}
