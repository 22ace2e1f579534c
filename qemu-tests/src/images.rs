//! Controller images for the HIL tests, emitted with `host_compiler::emit::ImageBuilder`.
//!
//! [`double_integrator`]: the double integrator `ẍ = u` sampled at h = 0.1 s with a feedforward table
//! (Algorithm 2, law (3.5)–(3.6)). Four nominal trajectories start at (±2, 0) and (0, ±2) and follow the
//! faster nominal law `ũ = K₂ x̃` (closed-loop poles 0.5); the table stores `v(κ) = ũ(κ) − K x̃(κ)` for the
//! tracking gain `K` (poles 0.8), so `u = K x + v(κ)` differs from `K x` and the error `x − x̃` decays
//! with `Ad + Bd K`. The balls use the Lyapunov metric `P` of `Ad + Bd K` (`AclᵀP Acl − P = −I`), with
//! radii a little under half the smallest centre distance, so they are disjoint. Past the table
//! (40 rows) the last row is held; the fallback is the linear law `u = K x` saturated to |u| ≤ 20.
//!
//! [`fl_4_9`]: the offset-thruster vehicle of Example 4.9 (`examples/fl-4-9.toml`, a feedback-linearizable
//! plant) with a hand-built image that carries model maps: `coords` ξ = (X, Ẋ, Y, Ẏ) and `input_map`
//! u = R(θ) w, R(θ) = [[−sin θ, cos θ], [cos θ, sin θ]], compiled from expressions with
//! `host_compiler::expr`. Since g(x)R(θ) adds w to (Ẍ, Ÿ), the ξ-system is linear affine, two copies of
//! `ẍ = 1 − x + 0.1ẋ + w` ((3.28)), sampled exactly here. One nominal from Init's centre to the goal
//! (2, 0) under a faster gain, tracked with `K` (both axes' poles at −2 s⁻¹); `P` is the Lyapunov metric
//! of the sampled closed loop and the ball covers Init's corners. Not certified: it exercises the
//! section, the interpreter and the loop. [`fl_4_9_certified`]: the certified image `synth` makes from
//! the same spec, [`fl_pendulum_certified`] the one of the torque-driven pendulum
//! (`examples/fl-pendulum.toml`), [`flat_quadrotor_certified`] the differentially flat planar quadrotor's
//! (`examples/flat-quadrotor.toml`, a controller with states of its own), and [`accepted_starts`] for
//! their runs.
#![allow(non_snake_case)]

use crate::plant::{double_integrator as double_integrator_plant, ContinuousPlant, DiscretePlant};
use faer::Mat;
use host_compiler::emit::{EmitError, FallbackLaw, ImageBuilder, ModelMapsSpec, Terminal};
use host_compiler::model::nonlinear::NonlinearPlant;
use host_compiler::model::ModelError;
use host_compiler::synth::{synthesize, SynthOptions, Synthesis};
use host_compiler::task::Task;
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
    #[error("the spec: {0}")]
    Spec(String),
    #[error("a model map: {0}")]
    Expr(#[from] host_compiler::expr::ExprError),
    #[error("the synthesis: {0}")]
    Synth(String),
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

/// The Example 4.9 image of the module doc and what the HIL test needs to know about it.
#[derive(Clone, Debug)]
pub struct NonlinearImage {
    /// The encoded image.
    pub bytes: Vec<u8>,
    /// The plant of the spec, `ẋ = f(x) + g(x)u`.
    pub plant: NonlinearPlant,
    /// Sample period, seconds.
    pub h: f64,
    /// Init's box (lo, hi) in the plant's state.
    pub init: (Vec<f64>, Vec<f64>),
    /// Rows of the table (the run's steps before the last row is held).
    pub table_len: usize,
    /// Bytes of the two model programs.
    pub program_bytes: usize,
}

impl NonlinearImage {
    /// The HIL runs' initial states: Init's four corners in (X, Y) and its centre, at Init's (Ẋ, Ẏ); θ and
    /// θ̇ zero (as Init has them) in two of them and off zero in the others, so that the maps' sin and
    /// cos see more than 0 from the first step on.
    pub fn starts(&self) -> Vec<Vec<f64>> {
        let (lo, hi) = &self.init;
        let mid = |i: usize| 0.5 * (lo[i] + hi[i]);
        vec![
            vec![lo[0], lo[1], lo[2], lo[3], 0.0, 0.0],
            vec![hi[0], lo[1], lo[2], lo[3], 0.0, 0.0],
            vec![lo[0], lo[1], hi[2], lo[3], 0.5, 0.0],
            vec![hi[0], lo[1], hi[2], lo[3], -1.0, 0.3],
            vec![mid(0), mid(1), mid(2), mid(3), 2.5, -0.4],
        ]
    }
}

/// Tracking gain of the ξ-system per axis (`ẍ = 1 − x + 0.1ẋ + w`, w = −3x − 4.1ẋ: s² + 4s + 4).
const FL_K_AXIS: [f64; 2] = [-3.0, -4.1];
/// The nominal's gain per axis (s² + 6s + 9).
const FL_K_NOMINAL_AXIS: [f64; 2] = [-8.0, -6.1];
/// Rows of the Example 4.9 table (3 s at h = 0.01 s).
pub const FL_TABLE_LEN: usize = 300;

/// `[[k, 0], [0, k]]` over ξ = (X, Ẋ, Y, Ẏ): 2×4 row-major.
fn per_axis(k: [f64; 2]) -> Vec<f64> {
    vec![k[0], k[1], 0.0, 0.0, 0.0, 0.0, k[0], k[1]]
}

/// The ξ-system of Example 4.9 under u = R(θ)w, ξ = (X, Ẋ, Y, Ẏ): per axis ẋ = v, v̇ = 1 − x + 0.1v + w.
pub fn fl_xi_system() -> ContinuousPlant {
    let A = Mat::from_fn(4, 4, |i, j| match (i % 2, j, i / 2) {
        (0, j, a) if j == 2 * a + 1 => 1.0,
        (1, j, a) if j == 2 * a => -1.0,
        (1, j, a) if j == 2 * a + 1 => 0.1,
        _ => 0.0,
    });
    let B = Mat::from_fn(4, 2, |i, j| if i == 2 * j + 1 { 1.0 } else { 0.0 });
    ContinuousPlant::new(A, B, vec![0.0, 1.0, 0.0, 1.0]).expect("the ξ-system is a valid plant")
}

/// The image of the module doc ([`fl_4_9`]'s data).
pub fn fl_4_9() -> Result<NonlinearImage, ImageBuildError> {
    use host_compiler::expr::compile::compile;
    use host_compiler::expr::{parse, Names};
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/fl-4-9.toml");
    let problem =
        host_compiler::spec::load(path).map_err(|e| ImageBuildError::Spec(format!("{e:?}")))?;
    let desc = problem
        .nonlinear
        .as_ref()
        .ok_or_else(|| ImageBuildError::Spec("fl-4-9 has no nonlinear plant".into()))?;
    let h = desc.period;
    let names = &desc.names;
    let params = names.param_values();
    let n_plant = names.states.len();
    let exprs = |texts: &[&str], names: &Names| -> Result<Vec<_>, ImageBuildError> {
        Ok(texts
            .iter()
            .map(|t| parse(t, names))
            .collect::<Result<Vec<_>, _>>()?)
    };
    let coords = compile(&exprs(&["X", "Xd", "Y", "Yd"], names)?, n_plant, 0, &params)?;
    let w_names = Names {
        inputs: vec!["w1".into(), "w2".into()],
        ..names.clone()
    };
    let input_map = compile(
        &exprs(
            &["-sin(th)*w1 + cos(th)*w2", "cos(th)*w1 + sin(th)*w2"],
            &w_names,
        )?,
        n_plant,
        2,
        &params,
    )?;

    let (n, m) = (4, 2);
    let d = fl_xi_system().zoh(h)?;
    let K = per_axis(FL_K_AXIS);
    let Acl = Mat::from_fn(n, n, |i, j| {
        d.A[(i, j)] + (0..m).map(|k| d.B[(i, k)] * K[k * n + j]).sum::<f64>()
    });
    let Pm = lyapunov(&Acl);
    let P: Vec<f64> = (0..n * n)
        .map(|k| 0.5 * (Pm[(k / n, k % n)] + Pm[(k % n, k / n)]))
        .collect();

    // The nominal: from ξ of Init's centre to the goal's equilibrium ξ = (2, 0, 0, 0), w = (1, −1).
    let (lo, hi) = (problem.init.lo.clone(), problem.init.hi.clone());
    let centre: Vec<f64> = lo.iter().zip(&hi).map(|(a, b)| 0.5 * (a + b)).collect();
    let xi0 = vec![centre[0], centre[1], centre[2], centre[3]];
    let (goal, w_eq) = ([2.0, 0.0, 0.0, 0.0], [1.0, -1.0]);
    let K2 = per_axis(FL_K_NOMINAL_AXIS);
    let (mut x_nom, mut u_nom) = (Vec::new(), Vec::new());
    let mut x = xi0.clone();
    for _ in 0..FL_TABLE_LEN {
        let u: Vec<f64> = (0..m)
            .map(|r| {
                w_eq[r]
                    + (0..n)
                        .map(|c| K2[r * n + c] * (x[c] - goal[c]))
                        .sum::<f64>()
            })
            .collect();
        x_nom.extend_from_slice(&x);
        u_nom.extend_from_slice(&u);
        x = d.step(&x, &u);
    }
    // The ball covers ξ of Init's corners (X and Y at their bounds), with 5 % to spare.
    let mut r2: f64 = 0.0;
    for (X, Y) in [
        (lo[0], lo[2]),
        (lo[0], hi[2]),
        (hi[0], lo[2]),
        (hi[0], hi[2]),
    ] {
        let e = [X - xi0[0], 0.0, Y - xi0[2], 0.0];
        r2 = r2.max(
            (0..n)
                .map(|i| (0..n).map(|j| e[i] * P[i * n + j] * e[j]).sum::<f64>())
                .sum(),
        );
    }
    let mut b = ImageBuilder::new(n, m, h);
    b.add_location(K, P);
    b.add_nominal_trajectory(&x_nom, &u_nom, &[0; FL_TABLE_LEN], 1.05 * r2.sqrt())?;
    b.fallback = FallbackLaw::Zero;
    b.terminal = Terminal::HoldLast;
    b.model_maps(ModelMapsSpec {
        n_plant,
        m_plant: names.inputs.len(),
        ext_init: Vec::new(),
        coords: coords.bytes.clone(),
        input_map: input_map.bytes.clone(),
    });
    let bytes = b.to_bytes()?;
    Ok(NonlinearImage {
        bytes,
        plant: NonlinearPlant::from_desc(desc),
        h,
        init: (lo, hi),
        table_len: FL_TABLE_LEN,
        program_bytes: coords.bytes.len() + input_map.bytes.len(),
    })
}

/// The certified Example 4.9 image as `synth` makes it from `examples/fl-4-9.toml` (its maps derived by
/// `model::feedback_linearizable`), with the task it was certified for; verified by Monte Carlo (64
/// interior states and 2 per ball), without the falsifier.
pub fn fl_4_9_certified() -> Result<(Task, Synthesis), ImageBuildError> {
    fl_certified(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/fl-4-9.toml"
    ))
}

/// The certified image of the torque-driven pendulum (`examples/fl-pendulum.toml`: a law that depends on
/// ξ, bounded over the spec's operating region), as [`fl_4_9_certified`] makes Example 4.9's.
pub fn fl_pendulum_certified() -> Result<(Task, Synthesis), ImageBuildError> {
    fl_certified(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/fl-pendulum.toml"
    ))
}

/// The certified image of the differentially flat planar quadrotor (`examples/flat-quadrotor.toml`: the
/// chain in its flat state q, the thrust and its rate kept by the controller), as [`fl_4_9_certified`]
/// makes Example 4.9's.
pub fn flat_quadrotor_certified() -> Result<(Task, Synthesis), ImageBuildError> {
    fl_certified(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/flat-quadrotor.toml"
    ))
}

/// The certified image `synth` makes from a feedback-linearizable spec, with its task; verified by Monte
/// Carlo (64 interior states and 2 per ball), without the falsifier.
fn fl_certified(path: &str) -> Result<(Task, Synthesis), ImageBuildError> {
    let problem =
        host_compiler::spec::load(path).map_err(|e| ImageBuildError::Spec(format!("{e:?}")))?;
    let task = Task::new(problem).map_err(|e| ImageBuildError::Spec(e.to_string()))?;
    let opts = SynthOptions {
        verify_interior: 64,
        verify_per_ball: 2,
        progress: false,
        attack: None,
        ..SynthOptions::default()
    };
    let s = synthesize(&task, &opts).map_err(|e| ImageBuildError::Synth(e.to_string()))?;
    Ok((task, s))
}

/// `count` initial plant states drawn in Init (seeded) whose ξ the image's selection accepts, for an image
/// of a feedback-linearizable task (of a flat one: ξ read with the controller's initial states ζ0, as a
/// run starts).
pub fn accepted_starts(
    task: &Task,
    image: image::Image<'_>,
    count: usize,
    seed: u64,
) -> Result<Vec<Vec<f64>>, ImageBuildError> {
    use rand::{Rng, SeedableRng};
    let maps = task
        .plant
        .linearization()
        .ok_or_else(|| ImageBuildError::Spec("not a feedback-linearizable task".into()))?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let ctl = shared_types::eval::Controller::new(image);
    let mut starts = Vec::new();
    while starts.len() < count {
        let x: Vec<f64> = maps
            .init
            .lo
            .iter()
            .zip(&maps.init.hi)
            .map(|(&l, &h)| if h > l { rng.random_range(l..=h) } else { l })
            .collect();
        let xi: Vec<f32> = maps.xi_of(&x).iter().map(|&v| v as f32).collect();
        if ctl.select_maps(&xi).is_some() {
            starts.push(x);
        }
    }
    Ok(starts)
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

    #[test]
    fn fl_4_9_image_carries_its_maps_and_flow_matches_the_linear_xi_system() {
        use crate::nonlinear::PlantFlow;
        let t = fl_4_9().unwrap();
        let img = image::decode(&t.bytes).unwrap();
        assert_eq!(
            (img.n(), img.m(), img.plant_n(), img.plant_m()),
            (4, 2, 6, 2)
        );
        let maps = img.model_maps().unwrap();
        assert_eq!(
            maps.coords_bytes().len() + maps.input_map_bytes().len(),
            t.program_bytes
        );
        // With F1 = F2 (aI = bI) and θ̇ = 0, θ stays put, so ξ follows the sampled linear ξ-system with
        // w = R(θ)u (R is its own inverse).
        let th: f64 = 0.4;
        let x0 = [0.05, 0.2, -0.03, 1.0, th, 0.0];
        let u = [0.7, 0.7];
        let x1 = PlantFlow::flow(&t.plant, &x0, &u, t.h).unwrap();
        let w = [
            -th.sin() * u[0] + th.cos() * u[1],
            th.cos() * u[0] + th.sin() * u[1],
        ];
        let d = fl_xi_system().zoh(t.h).unwrap();
        let xi1 = d.step(&[x0[0], x0[1], x0[2], x0[3]], &w);
        for i in 0..4 {
            assert!(
                (x1[i] - xi1[i]).abs() < 1e-9,
                "{i}: {} vs {}",
                x1[i],
                xi1[i]
            );
        }
        assert!((x1[4] - th).abs() < 1e-12 && x1[5].abs() < 1e-12);
    }

    #[test]
    fn fl_4_9_host_loop_tracks_to_the_goal() {
        use crate::nonlinear::PlantFlow;
        let t = fl_4_9().unwrap();
        let img = image::decode(&t.bytes).unwrap();
        for x0 in [
            vec![t.init.0[0], 0.0, t.init.0[2], 1.0, 0.0, 0.0],
            vec![t.init.1[0], 0.0, t.init.0[2], 1.0, 0.3, -0.2],
        ] {
            let mut c = shared_types::eval::Controller::new(img);
            let mut x = x0.clone();
            for k in 0..FL_TABLE_LEN + 100 {
                let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
                let u = c
                    .step_plant(&xf)
                    .unwrap_or_else(|s| panic!("step {k} from {x0:?}: {s:?}"));
                let u: Vec<f64> = u.as_slice().iter().map(|&v| v as f64).collect();
                x = PlantFlow::flow(&t.plant, &x, &u, t.h).unwrap();
            }
            assert!(
                (x[0] - 2.0).abs() < 0.02 && x[2].abs() < 0.02,
                "from {x0:?} ends at {x:?}"
            );
        }
    }
}
