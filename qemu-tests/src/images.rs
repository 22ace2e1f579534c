//! Controller images for the HIL tests, emitted with `host_compiler::emit::ImageBuilder`.
//!
//! [`double_integrator`]: the double integrator `ẍ = u` sampled at h = 0.1 s with a feedforward table
//! (Algorithm 2, law (3.5)–(3.6)). Four nominal trajectories start at (±2, 0) and (0, ±2) and follow the
//! faster nominal law `ũ = K₂ x̃` (closed-loop poles 0.5); the table stores `v(κ) = ũ(κ) − K x̃(κ)` for the
//! tracking gain `K` (poles 0.8), so `u = K x + v(κ)` differs from `K x` and the error `x − x̃` decays
//! with `Ad + Bd K`. The balls use the Lyapunov metric `P` of `Ad + Bd K` (`AclᵀP Acl − P = −I`), with
//! radii a little under half the smallest centre distance, so they are disjoint. Past the table
//! (40 rows) the last row is held; the fallback is the linear law `u = K x` saturated to |u| ≤ 20.
#![allow(non_snake_case)]

use crate::plant::{double_integrator as double_integrator_plant, ContinuousPlant, DiscretePlant};
use faer::Mat;
use host_compiler::emit::{EmitError, FallbackLaw, ImageBuilder, Terminal};
use host_compiler::model::ModelError;
use shared_types::image;

/// A test image with what the tests need to know about it.
#[derive(Clone, Debug)]
pub struct TestImage {
    /// The encoded image.
    pub bytes: Vec<u8>,
    /// The continuous plant it was designed for.
    pub plant: ContinuousPlant,
    /// Its exact zero-order-hold sampling with the image's period.
    pub sampled: DiscretePlant,
    /// Sample period, seconds.
    pub h: f64,
    /// Ball centres (f32 values as stored).
    pub centres: Vec<Vec<f32>>,
    /// Ball radii as stored.
    pub deltas: Vec<f32>,
    /// The ball metric as stored (n×n row-major).
    pub P: Vec<f32>,
}

impl TestImage {
    /// The plant sampled with the image's period.
    pub fn discrete_plant(&self) -> DiscretePlant {
        self.sampled.clone()
    }

    /// `(x − c)ᵀ P (x − c)` in f64, for choosing test states inside or outside balls.
    pub fn dist2(&self, x: &[f64], ball: usize) -> f64 {
        let n = x.len();
        let e: Vec<f64> = x
            .iter()
            .zip(&self.centres[ball])
            .map(|(a, &c)| a - c as f64)
            .collect();
        (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| e[i] * self.P[i * n + j] as f64 * e[j])
                    .sum::<f64>()
            })
            .sum()
    }

    /// Whether `x` lies in no ball (with a safety margin of 1 %).
    pub fn outside_every_ball(&self, x: &[f64]) -> bool {
        (0..self.deltas.len()).all(|i| self.dist2(x, i) > 1.01 * (self.deltas[i] as f64).powi(2))
    }
}

/// Why a test image could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ImageBuildError {
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error(transparent)]
    Emit(#[from] EmitError),
    #[error(transparent)]
    Image(#[from] image::ImageError),
}

/// Tracking gain `K` (closed-loop poles of the sampled double integrator at 0.8, 0.8, h = 0.1).
pub const K_TRACK: [f64; 2] = [-4.0, -3.8];
/// Nominal gain `K₂` (poles at 0.5, 0.5).
pub const K_NOMINAL: [f64; 2] = [-25.0, -8.75];
/// Rows per trajectory.
pub const TABLE_LEN: usize = 40;

/// `Acl = Ad + Bd K` for a single-input plant.
pub fn closed_loop(d: &DiscretePlant, K: &[f64]) -> Mat<f64> {
    let n = d.A.nrows();
    Mat::from_fn(n, n, |i, j| d.A[(i, j)] + d.B[(i, 0)] * K[j])
}

/// `P = Σ_k (Aclᵀ)^k Acl^k`, the solution of `Aclᵀ P Acl − P = −I` for a Schur-stable `Acl`, summed until
/// the terms vanish in f64 (at most 10 000 terms).
pub fn lyapunov(Acl: &Mat<f64>) -> Mat<f64> {
    let n = Acl.nrows();
    let mut P = Mat::<f64>::zeros(n, n);
    let mut Ak = Mat::<f64>::identity(n, n);
    for _ in 0..10_000 {
        let term = Ak.transpose() * &Ak;
        P += &term;
        let largest = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .map(|(i, j)| term[(i, j)].abs())
            .fold(0.0, f64::max);
        if largest < 1e-18 {
            break;
        }
        Ak = &Ak * Acl;
    }
    P
}

/// The double-integrator feedforward image described in the module doc, emitted by the host compiler's
/// [`ImageBuilder`] (so the HIL suite also exercises the real emitter).
pub fn double_integrator() -> Result<TestImage, ImageBuildError> {
    let plant = double_integrator_plant();
    let h = 0.1;
    let d = plant.zoh(h)?;
    let n = 2;
    let Acl = closed_loop(&d, &K_TRACK);
    let Pm = lyapunov(&Acl);
    // Exactly symmetric (the decoder checks symmetry bit for bit).
    let P: Vec<f64> = (0..n * n)
        .map(|k| 0.5 * (Pm[(k / n, k % n)] + Pm[(k % n, k / n)]))
        .collect();
    let starts: [[f64; 2]; 4] = [[2.0, 0.0], [-2.0, 0.0], [0.0, 2.0], [0.0, -2.0]];
    let pdist = |a: &[f64; 2], b: &[f64; 2]| {
        let e = [a[0] - b[0], a[1] - b[1]];
        (0..n)
            .map(|i| (0..n).map(|j| e[i] * P[i * n + j] * e[j]).sum::<f64>())
            .sum::<f64>()
            .sqrt()
    };
    let mut min_dist = f64::INFINITY;
    for (i, a) in starts.iter().enumerate() {
        for b in &starts[i + 1..] {
            min_dist = min_dist.min(pdist(a, b));
        }
    }
    let mut b = ImageBuilder::new(n, 1, h);
    b.add_location(K_TRACK.to_vec(), P);
    for s in &starts {
        let (mut x_nom, mut u_nom) = (Vec::new(), Vec::new());
        let mut x = s.to_vec();
        for _ in 0..TABLE_LEN {
            let u: f64 = K_NOMINAL.iter().zip(&x).map(|(k, xi)| k * xi).sum();
            x_nom.extend_from_slice(&x);
            u_nom.push(u);
            x = d.step(&x, &[u]);
        }
        b.add_nominal_trajectory(&x_nom, &u_nom, &[0; TABLE_LEN], 0.45 * min_dist)?;
    }
    b.fallback = FallbackLaw::Linear {
        K: K_TRACK.to_vec(),
        x_ref: vec![0.0; n],
        u_ref: vec![0.0],
    };
    b.input_box = Some((vec![-20.0], vec![20.0]));
    b.terminal = Terminal::HoldLast;
    let bytes = b.to_bytes()?;
    // What the tests know about the image is read back from it: the values as stored in f32.
    let img = image::decode(&bytes)?;
    let centres = (0..starts.len())
        .map(|t| (0..n).map(|i| img.centre(t, i)).collect())
        .collect();
    let deltas = (0..starts.len()).map(|t| img.delta(t)).collect();
    let P = (0..n * n).map(|k| img.P(0, k / n, k % n)).collect();
    Ok(TestImage {
        bytes,
        plant,
        sampled: d,
        h,
        centres,
        deltas,
        P,
    })
}

/// A copy of `bytes` with one payload byte flipped: the CRC no longer matches, the header still parses.
pub fn corrupted(bytes: &[u8]) -> Vec<u8> {
    let mut b = bytes.to_vec();
    let i = shared_types::capacity::HEADER_LEN + (b.len() - shared_types::capacity::HEADER_LEN) / 2;
    if let Some(x) = b.get_mut(i) {
        *x ^= 0x5a;
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spectral_radius_2x2(m: &Mat<f64>) -> f64 {
        let (tr, det) = (
            m[(0, 0)] + m[(1, 1)],
            m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)],
        );
        let disc = tr * tr / 4.0 - det;
        if disc >= 0.0 {
            (tr / 2.0).abs() + disc.sqrt()
        } else {
            det.sqrt()
        }
    }

    #[test]
    fn gains_place_the_documented_poles() {
        let d = double_integrator_plant().zoh(0.1).unwrap();
        for (K, pole) in [(K_TRACK, 0.8), (K_NOMINAL, 0.5)] {
            let a = closed_loop(&d, &K);
            let tr = a[(0, 0)] + a[(1, 1)];
            let det = a[(0, 0)] * a[(1, 1)] - a[(0, 1)] * a[(1, 0)];
            assert!(
                (tr - 2.0 * pole).abs() < 1e-12 && (det - pole * pole).abs() < 1e-12,
                "{K:?}"
            );
            assert!(spectral_radius_2x2(&a) < 1.0);
        }
    }

    #[test]
    fn lyapunov_solution_satisfies_the_equation() {
        let d = double_integrator_plant().zoh(0.1).unwrap();
        let a = closed_loop(&d, &K_TRACK);
        let p = lyapunov(&a);
        for i in 0..2 {
            for j in 0..2 {
                // (Aᵀ P A − P)_ij = −δ_ij
                let apa: f64 = (0..2)
                    .map(|k| {
                        (0..2)
                            .map(|l| a[(k, i)] * p[(k, l)] * a[(l, j)])
                            .sum::<f64>()
                    })
                    .sum();
                let want = if i == j { -1.0 } else { 0.0 };
                assert!((apa - p[(i, j)] - want).abs() < 1e-9, "({i},{j})");
            }
        }
    }

    #[test]
    fn image_decodes_and_balls_are_disjoint() {
        let t = double_integrator().unwrap();
        let img = image::decode(&t.bytes).unwrap();
        assert_eq!(
            (img.n(), img.m(), img.n_trajectories(), img.total_steps()),
            (2, 1, 4, 4 * TABLE_LEN)
        );
        for i in 0..4 {
            let c: Vec<f64> = t.centres[i].iter().map(|&v| v as f64).collect();
            assert_eq!(t.dist2(&c, i), 0.0);
            for j in (0..4).filter(|&j| j != i) {
                assert!(t.dist2(&c, j).sqrt() > 2.0 * t.deltas[j] as f64);
            }
        }
        assert!(t.outside_every_ball(&[10.0, 10.0]));
        assert!(image::decode(&corrupted(&t.bytes)).is_err());
    }
}
