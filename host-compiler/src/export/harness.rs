//! The differential check of the C export: compiles the exported evaluator with the system C compiler
//! (`cc`, or `$CC`) under the flags the generated header names, drives it with a sequence of [`Op`]s and
//! compares every answer with the Rust evaluator (`shared_types::eval::Controller`) bit for bit; plus the
//! seeded scenarios ([`scenario`]) and synthetic images of every mode ([`feedforward_image`],
//! [`pwa_image`]) the tests and the `c_export` bench run it on. Not used by the pipeline.
//!
//! A step's answer is its status and all `MAX_M` input values: on `Ok` the input, otherwise the image's
//! fallback at that state given the last applied input (what the firmware applies). An init's answer is
//! whether the image was accepted (the C error codes are coarser than `ImageError`).
#![allow(non_snake_case)]

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use shared_types::capacity::MAX_M;
use shared_types::eval::{Controller, Input, Status};
use shared_types::image::{decode, Image, Mode, Terminal};

use crate::emit::{
    CertifiedBall, Child, FallbackLaw, ImageBuilder, PwaImageBuilder, PwaLaw, PwaLeaf,
    TrajectoryEntry, TreeNode,
};

/// The flags the exported C must be compiled with for bit-for-bit equality (see `controller.h`).
pub const CFLAGS: [&str; 4] = ["-std=c99", "-O2", "-ffp-contract=off", "-fno-fast-math"];

/// The driver the harness compiles with the export (protocol in its comment).
const DRIVER_C: &str = include_str!("c/harness_driver.c");

/// One command to both evaluators.
#[derive(Clone, Debug, PartialEq)]
pub enum Op {
    /// Init from these bytes (any bytes: corrupted images are refused by both or the check fails).
    InitBytes(Vec<u8>),
    /// Init from the exported `sc_image_bytes` array (the Rust side uses the image the harness was built for).
    InitEmbedded,
    /// Back to κ = 0.
    Reset,
    /// One period with this state (any length, any values).
    Step(Vec<f32>),
}

/// One answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Answer {
    /// Whether the image was accepted.
    Init(bool),
    /// Status (wire value) and the bits of the `MAX_M` input values.
    Step(u8, [u32; MAX_M]),
}

/// What a comparison found.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Comparison {
    /// Steps compared.
    pub states: usize,
    /// Steps whose status or an input bit differed.
    pub mismatches: usize,
    /// Inits compared.
    pub inits: usize,
    /// Inits where one side accepted and the other refused.
    pub init_mismatches: usize,
    /// Steps per status wire value (`Ok`, `OutOfEnvelope`, `BadFrame`, `ImageRejected`), Rust side.
    pub by_status: [usize; 4],
    /// The first difference, described.
    pub first: Option<String>,
}

/// Why the harness could not run.
#[derive(Debug, thiserror::Error)]
pub enum HarnessError {
    /// Writing the export or the driver failed, or the image was rejected by the exporter.
    #[error("export: {0}")]
    Export(#[from] super::c::ExportError),
    /// An I/O error around the compiler or the driver.
    #[error("{what}: {source}")]
    Io {
        /// What was being done.
        what: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The compiler failed.
    #[error("the C compiler failed:\n{0}")]
    Compile(String),
    /// The driver failed or answered in an unexpected format.
    #[error("the C driver failed: {0}")]
    Driver(String),
}

fn io(what: &str) -> impl FnOnce(std::io::Error) -> HarnessError + '_ {
    move |source| HarnessError::Io {
        what: what.to_string(),
        source,
    }
}

/// The exported evaluator compiled with the driver, for one image.
pub struct CHarness {
    exe: PathBuf,
    image: Vec<u8>,
}

impl CHarness {
    /// Exports `image` into `dir`, writes the driver there and compiles both with `$CC` (default `cc`)
    /// and [`CFLAGS`] plus warnings as errors.
    pub fn build(image: &[u8], dir: &Path) -> Result<CHarness, HarnessError> {
        super::c::write(image, dir)?;
        let driver = dir.join("harness_driver.c");
        std::fs::write(&driver, DRIVER_C).map_err(io("writing the driver"))?;
        let exe = dir.join("harness_driver");
        let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
        let out = Command::new(&cc)
            .args(CFLAGS)
            .args(["-Wall", "-Wextra", "-Werror", "-pedantic", "-o"])
            .arg(&exe)
            .arg(dir.join("controller.c"))
            .arg(dir.join("controller_image.c"))
            .arg(&driver)
            .output()
            .map_err(io("running the C compiler"))?;
        if !out.status.success() {
            return Err(HarnessError::Compile(
                String::from_utf8_lossy(&out.stderr).into_owned(),
            ));
        }
        Ok(CHarness {
            exe,
            image: image.to_vec(),
        })
    }

    /// Runs `ops` through the C driver and returns its answers.
    pub fn run_c(&self, ops: &[Op]) -> Result<Vec<Answer>, HarnessError> {
        let mut input = Vec::new();
        for op in ops {
            match op {
                Op::InitBytes(b) => {
                    input.push(b'I');
                    let len = u32::try_from(b.len())
                        .map_err(|_| HarnessError::Driver("image too long".into()))?;
                    input.extend_from_slice(&len.to_le_bytes());
                    input.extend_from_slice(b);
                }
                Op::InitEmbedded => input.push(b'E'),
                Op::Reset => input.push(b'R'),
                Op::Step(x) => {
                    let k = u8::try_from(x.len())
                        .ok()
                        .filter(|&k| k <= 16)
                        .ok_or_else(|| HarnessError::Driver("state longer than 16".into()))?;
                    input.push(b'S');
                    input.push(k);
                    for v in x {
                        input.extend_from_slice(&v.to_le_bytes());
                    }
                }
            }
        }
        let mut child = Command::new(&self.exe)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(io("starting the C driver"))?;
        // Feed stdin from a thread so that a full stdout pipe cannot deadlock us.
        let mut stdin = child
            .stdin
            .take()
            .ok_or_else(|| HarnessError::Driver("no stdin".into()))?;
        let feeder = std::thread::spawn(move || stdin.write_all(&input));
        let out = child
            .wait_with_output()
            .map_err(io("waiting for the C driver"))?;
        let fed = feeder
            .join()
            .map_err(|_| HarnessError::Driver("stdin thread failed".into()))?;
        fed.map_err(io("writing to the C driver"))?;
        if !out.status.success() {
            return Err(HarnessError::Driver(format!(
                "exit status {}: {}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
            )));
        }
        let mut answers = Vec::new();
        let mut bytes = out.stdout.as_slice();
        for op in ops {
            match op {
                Op::Reset => {}
                Op::InitBytes(_) | Op::InitEmbedded => {
                    let (&e, rest) = bytes
                        .split_first()
                        .ok_or_else(|| HarnessError::Driver("short answer".into()))?;
                    answers.push(Answer::Init(e == 0));
                    bytes = rest;
                }
                Op::Step(_) => {
                    let rec = 1 + 4 * MAX_M;
                    let (head, rest) = bytes
                        .split_at_checked(rec)
                        .ok_or_else(|| HarnessError::Driver("short answer".into()))?;
                    let mut u = [0u32; MAX_M];
                    for (j, c) in head[1..].chunks_exact(4).enumerate() {
                        u[j] = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                    }
                    answers.push(Answer::Step(head[0], u));
                    bytes = rest;
                }
            }
        }
        if !bytes.is_empty() {
            return Err(HarnessError::Driver("trailing answer bytes".into()));
        }
        Ok(answers)
    }

    /// Runs `ops` through the Rust evaluator, as the driver runs them through the C one.
    pub fn run_rust(&self, ops: &[Op]) -> Vec<Answer> {
        reference(&self.image, ops)
    }

    /// Runs `ops` through both and compares.
    pub fn compare(&self, ops: &[Op]) -> Result<Comparison, HarnessError> {
        let c = self.run_c(ops)?;
        let r = self.run_rust(ops);
        let mut out = Comparison::default();
        if c.len() != r.len() {
            return Err(HarnessError::Driver(format!(
                "{} answers from C, {} from Rust",
                c.len(),
                r.len()
            )));
        }
        let mut step = 0usize;
        for (i, (a, b)) in c.iter().zip(&r).enumerate() {
            match (a, b) {
                (Answer::Init(x), Answer::Init(y)) => {
                    out.inits += 1;
                    if x != y {
                        out.init_mismatches += 1;
                        out.first.get_or_insert_with(|| {
                            format!("answer {i}: C accepted = {x}, Rust accepted = {y}")
                        });
                    }
                }
                (Answer::Step(sa, ua), Answer::Step(sb, ub)) => {
                    out.states += 1;
                    if let Some(k) = out.by_status.get_mut(*sb as usize) {
                        *k += 1;
                    }
                    if sa != sb || ua != ub {
                        out.mismatches += 1;
                        out.first.get_or_insert_with(|| {
                            format!(
                                "step {step} (answer {i}): C status {sa} u {:?}, Rust status {sb} u {:?}",
                                ua.map(f32::from_bits),
                                ub.map(f32::from_bits)
                            )
                        });
                    }
                    step += 1;
                }
                _ => return Err(HarnessError::Driver(format!("answer {i}: kinds differ"))),
            }
        }
        Ok(out)
    }
}

/// The Rust evaluator's answers to `ops` (`InitEmbedded` uses `image`).
pub fn reference(image: &[u8], ops: &[Op]) -> Vec<Answer> {
    let mut ctl: Option<Controller<'_>> = None;
    let mut applied = Input::zero(0);
    let mut answers = Vec::new();
    for op in ops {
        match op {
            Op::InitBytes(_) | Op::InitEmbedded => {
                let bytes: &[u8] = match op {
                    Op::InitBytes(b) => b,
                    _ => image,
                };
                ctl = decode(bytes).ok().map(Controller::new);
                applied = Input::zero(ctl.as_ref().map_or(0, |c| c.image().m()));
                answers.push(Answer::Init(ctl.is_some()));
            }
            Op::Reset => {
                if let Some(c) = ctl.as_mut() {
                    c.reset();
                    applied = Input::zero(c.image().m());
                }
            }
            Op::Step(x) => {
                let (status, u) = match ctl.as_mut() {
                    None => (Status::ImageRejected, Input::zero(0)),
                    Some(c) => match c.step(x) {
                        Ok(u) => (Status::Ok, u),
                        Err(s) => (s, c.fallback(x, &applied)),
                    },
                };
                applied = u;
                answers.push(Answer::Step(status as u8, u.values().map(f32::to_bits)));
            }
        }
    }
    answers
}

// ---------------------------------------------------------------------------------------------------------
// Scenarios.

fn normal(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

/// A radius factor: inside (60 %), on the boundary up to a few ulps (25 %), outside (15 %).
fn radius_factor(rng: &mut ChaCha8Rng) -> f64 {
    let r: f64 = rng.random();
    if r < 0.6 {
        rng.random::<f64>()
    } else if r < 0.85 {
        1.0 + (rng.random::<f64>() - 0.5) * 1e-6
    } else {
        1.0 + rng.random::<f64>() * 2.0
    }
}

/// Occasionally an unusable or extreme state instead of `x`: wrong length, NaN, infinity, or huge
/// components (whose input overflows); else `x` itself.
fn perturb(rng: &mut ChaCha8Rng, x: Vec<f32>) -> Vec<f32> {
    let r: f64 = rng.random();
    let n = x.len();
    if r < 0.005 {
        x[..n - 1].to_vec()
    } else if r < 0.01 {
        let mut y = x;
        y.push(0.0);
        y
    } else if r < 0.015 {
        let mut y = x;
        y[rng.random_range(0..n)] = f32::NAN;
        y
    } else if r < 0.02 {
        let mut y = x;
        y[rng.random_range(0..n)] = f32::INFINITY;
        y
    } else if r < 0.025 {
        x.iter().map(|v| v * 3.0e37).collect()
    } else {
        x
    }
}

/// `c + s·e/q` in f32, with `e` a random direction and `q` its length in the metric `norm`.
fn point_at(rng: &mut ChaCha8Rng, c: &[f64], s: f64, norm: impl Fn(&[f64]) -> f64) -> Vec<f32> {
    let e: Vec<f64> = c.iter().map(|_| normal(rng)).collect();
    let q = norm(&e).max(1e-300);
    c.iter()
        .zip(&e)
        .map(|(ci, ei)| (ci + s * ei / q) as f32)
        .collect()
}

/// A seeded scenario of at least `states` steps for `image`, starting with [`Op::InitEmbedded`].
///
/// Feedforward: runs of steps from a reset, whose first state lies inside a ball, on its boundary (to a
/// few ulps) or outside it, continued past the trajectory's end (so the segment cursor, each location's
/// gain, the terminal behaviour and the out-of-envelope latch are exercised). PWA: states inside, on and
/// outside the certified balls (in their own whitened metric) and across the whole envelope's bounding
/// box. Both: about 2.5 % unusable or overflowing states.
pub fn scenario(image: &Image<'_>, seed: u64, states: usize) -> Vec<Op> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = image.n();
    let mut ops = vec![Op::InitEmbedded];
    let mut count = 0usize;
    match image.mode() {
        Mode::Feedforward => {
            while count < states {
                ops.push(Op::Reset);
                let t = rng.random_range(0..image.n_trajectories());
                let (s0, _) = image.trajectory_segments(t);
                let l = image.segment(s0).map_or(0, |s| s.location);
                let c: Vec<f64> = (0..n).map(|i| image.centre(t, i) as f64).collect();
                let delta = image.delta(t) as f64;
                let norm = |e: &[f64]| {
                    let mut q = 0.0;
                    for r in 0..n {
                        for k in 0..n {
                            q += e[r] * image.P(l, r, k) as f64 * e[k];
                        }
                    }
                    q.max(0.0).sqrt()
                };
                let rho = radius_factor(&mut rng);
                let x0 = point_at(&mut rng, &c, delta * rho, norm);
                let len = image.trajectory_len(t) + rng.random_range(0..4);
                let len = if rng.random::<f64>() < 0.2 {
                    rng.random_range(1..=len)
                } else {
                    len
                };
                let mut x = x0;
                for _ in 0..len {
                    ops.push(Op::Step(perturb(&mut rng, x.clone())));
                    count += 1;
                    for v in x.iter_mut() {
                        *v += (0.05 * normal(&mut rng)) as f32;
                    }
                }
            }
        }
        _ => {
            let nb = image.n_balls();
            let mut lo = vec![f64::INFINITY; n];
            let mut hi = vec![f64::NEG_INFINITY; n];
            for b in 0..nb {
                for i in 0..n {
                    let c = image.ball_centre(b, i) as f64;
                    lo[i] = lo[i].min(c - 1.0);
                    hi[i] = hi[i].max(c + 1.0);
                }
            }
            while count < states {
                if rng.random::<f64>() < 0.001 {
                    ops.push(Op::Reset);
                }
                let x = if rng.random::<f64>() < 0.8 {
                    let b = rng.random_range(0..nb);
                    let l = image.ball_location(b);
                    let c: Vec<f64> = (0..n).map(|i| image.ball_centre(b, i) as f64).collect();
                    let s = (image.ball_threshold(b) as f64).sqrt();
                    let norm = |e: &[f64]| {
                        let mut q = 0.0;
                        for r in 0..n {
                            let mut z = 0.0;
                            for (k, ek) in e.iter().enumerate().skip(r) {
                                z += image.factor(l, r, k) as f64 * ek;
                            }
                            q += z * z;
                        }
                        q.sqrt()
                    };
                    let rho = radius_factor(&mut rng);
                    point_at(&mut rng, &c, s * rho, norm)
                } else {
                    (0..n)
                        .map(|i| rng.random_range(lo[i]..hi[i]) as f32)
                        .collect()
                };
                ops.push(Op::Step(perturb(&mut rng, x)));
                count += 1;
            }
        }
    }
    ops
}

// ---------------------------------------------------------------------------------------------------------
// Synthetic images.

/// A random symmetric positive definite n×n matrix (exactly symmetric).
fn random_spd(rng: &mut ChaCha8Rng, n: usize) -> Vec<f64> {
    let a: Vec<f64> = (0..n * n).map(|_| normal(rng)).collect();
    let mut p = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            let mut s = 0.0;
            for k in 0..n {
                s += a[k * n + i] * a[k * n + j];
            }
            p[i * n + j] = s + if i == j { 0.5 * n as f64 } else { 0.0 };
        }
    }
    p
}

fn random_vec(rng: &mut ChaCha8Rng, len: usize, scale: f64) -> Vec<f64> {
    (0..len).map(|_| scale * normal(rng)).collect()
}

/// The fallback laws a synthetic image can carry, by index 0..4: hold, zero, linear (with the input
/// box), constant.
fn fallback_law(rng: &mut ChaCha8Rng, which: usize, n: usize, m: usize) -> FallbackLaw {
    match which % 4 {
        0 => FallbackLaw::Hold,
        1 => FallbackLaw::Zero,
        2 => FallbackLaw::Linear {
            K: random_vec(rng, m * n, 1.0),
            x_ref: random_vec(rng, n, 0.5),
            u_ref: random_vec(rng, m, 0.2),
        },
        _ => FallbackLaw::Constant((0..m).map(|_| rng.random_range(-0.5..0.5)).collect()),
    }
}

/// A seeded synthetic feedforward image: `locations` locations (each trajectory visits them in runs, so a
/// multi-location image has several segments per trajectory), `trajectories` balls with overlapping
/// radii, tables of 5 to 40 rows, the given terminal behaviour and fallback law (index as in the
/// harness: 0 hold, 1 zero, 2 linear, 3 constant), and an input box `[-1, 1]^m`.
pub fn feedforward_image(
    seed: u64,
    n: usize,
    m: usize,
    locations: usize,
    trajectories: usize,
    terminal: Terminal,
    fallback: usize,
) -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut b = ImageBuilder::new(n, m, 0.05);
    for _ in 0..locations {
        let K = random_vec(&mut rng, m * n, 1.0);
        let P = random_spd(&mut rng, n);
        b.add_location(K, P);
    }
    for _ in 0..trajectories {
        let len = rng.random_range(5..=40);
        let mut location = Vec::with_capacity(len);
        let mut l = rng.random_range(0..locations);
        for _ in 0..len {
            if locations > 1 && rng.random::<f64>() < 0.15 {
                l = (l + rng.random_range(1..locations)) % locations;
            }
            location.push(l as u8);
        }
        b.add_trajectory(TrajectoryEntry {
            x0: random_vec(&mut rng, n, 1.0),
            delta: rng.random_range(0.3..2.0),
            v: random_vec(&mut rng, len * m, 0.5),
            location,
        });
    }
    b.fallback = fallback_law(&mut rng, fallback, n, m);
    b.input_box = Some((vec![-1.0; m], vec![1.0; m]));
    b.terminal = terminal;
    b.to_bytes().expect("a valid synthetic feedforward image")
}

/// A seeded synthetic PWA-feedback image: a complete tree of depth 3 over random hyperplanes (one of its
/// eight child slots outside the envelope, so seven leaves), `partitions` laws, `balls` balls in
/// `locations` metrics; each leaf lists the balls whose centre the tree routes to it and a few others
/// (mixed partitions), fallback law by index as in [`feedforward_image`].
pub fn pwa_image(
    seed: u64,
    n: usize,
    m: usize,
    locations: usize,
    partitions: usize,
    balls: usize,
    fallback: usize,
) -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut b = PwaImageBuilder::new(n, m, 0.05);
    for _ in 0..locations {
        let K = random_vec(&mut rng, m * n, 1.0);
        let P = random_spd(&mut rng, n);
        b.add_location(K, P);
    }
    for _ in 0..partitions {
        b.add_law(PwaLaw {
            gain: random_vec(&mut rng, m * n, 1.0),
            offset: random_vec(&mut rng, m, 0.3),
        });
    }
    // Nodes 0..7 (heap order); node i's children are 2i+1, 2i+2, and past node 6 leaves 0..7, of which
    // the slot of "leaf 7" is outside.
    let mut planes = Vec::new();
    for i in 0..7usize {
        let a = random_vec(&mut rng, n, 1.0);
        let bb = 0.3 * normal(&mut rng);
        planes.push((a.clone(), bb));
        let child = |k: usize| {
            if k < 7 {
                Child::Node(k as u16)
            } else if k - 7 < 7 {
                Child::Leaf((k - 7) as u16)
            } else {
                Child::Outside
            }
        };
        b.add_node(TreeNode {
            a,
            b: bb,
            left: child(2 * i + 1),
            right: child(2 * i + 2),
        });
    }
    let route = |x: &[f64]| -> Option<usize> {
        let mut i = 0usize;
        loop {
            let (a, bb) = &planes[i];
            let s: f64 = a.iter().zip(x).map(|(p, q)| p * q).sum();
            let k = if s <= *bb { 2 * i + 1 } else { 2 * i + 2 };
            if k < 7 {
                i = k;
            } else {
                return (k - 7 < 7).then_some(k - 7);
            }
        }
    };
    let mut leaf_balls = vec![Vec::new(); 7];
    for k in 0..balls {
        let centre = random_vec(&mut rng, n, 1.5);
        if let Some(l) = route(&centre) {
            leaf_balls[l].push(k);
        }
        let r: f64 = rng.random_range(0.2..0.9);
        b.add_ball(CertifiedBall {
            centre,
            threshold: r * r,
            location: rng.random_range(0..locations) as u8,
            partition: rng.random_range(0..partitions),
        });
    }
    for lb in leaf_balls.iter_mut() {
        for _ in 0..3 {
            let k = rng.random_range(0..balls);
            if !lb.contains(&k) {
                lb.push(k);
            }
        }
        lb.truncate(shared_types::capacity::MAX_LEAF_BALLS);
    }
    for lb in leaf_balls {
        b.add_leaf(PwaLeaf {
            partition: rng.random_range(0..partitions),
            balls: lb,
        });
    }
    b.fallback = fallback_law(&mut rng, fallback, n, m);
    b.input_box = Some((vec![-1.0; m], vec![1.0; m]));
    b.to_bytes().expect("a valid synthetic PWA image")
}
