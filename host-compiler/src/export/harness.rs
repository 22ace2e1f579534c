//! The differential check of the C export: compiles the exported evaluator with the system C compiler
//! (`cc`, or `$CC`) under the flags the generated header names, drives it with a sequence of [`Op`]s and
//! compares every answer with the Rust evaluator (`shared_types::eval::Controller`) bit for bit; plus the
//! seeded scenarios ([`scenario`], [`exits_scenario`]) and synthetic images of every mode
//! ([`feedforward_image`], [`exits_image`]: feedforward with segment exits, [`pwa_image`], [`maps_image`]:
//! feedforward with model maps, [`ext_image`]: model maps with controller states) the tests and the
//! `c_export` bench run it on. Not used by the pipeline.
//!
//! Model programs that call `tan`, `exp`, `log`, `atan`, `tanh` or `atan2` run the C library's
//! functions in C and the `libm` crate's in Rust, which may differ in the last place (`sin` and `cos`
//! are `shared_types::trig::sincos` on both sides, ported, so the same bits):
//! [`CHarness::compare_within`] then accepts inputs that differ by at most a given number of ulps (and
//! reports the largest difference it saw); everything else is compared bit for bit.
//!
//! A step's answer is its status and all `MAX_M` input values: on `Ok` the input, otherwise the image's
//! fallback at that state given the last applied input (what the firmware applies). An init's answer is
//! whether the image was accepted (the C error codes are coarser than `ImageError`).
//!
//! The task's monitor (section 14) is driven by its own ops ([`Op::MonitorInit`], [`Op::MonitorReset`],
//! [`Op::MonitorUpdate`]) against `shared_types::monitor::Monitor`: the init's outcome and the arena's
//! words, and every update's bounds (bits) and verdict; [`monitor_scenario`] makes seeded traces for an
//! image with a monitor (paths through its atoms' sets and across their boundaries, or a caller's paths,
//! with NaN, infinite, huge and wrongly sized states mixed in).
#![allow(non_snake_case)]

use std::collections::BTreeSet;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use shared_types::capacity::MAX_M;
use shared_types::eval::{Controller, Input, Status};
use shared_types::image::{decode, Exit, Image, Mode, Terminal};
use shared_types::monitor::{Monitor, MonitorProgram, ATOM_BALL, ATOM_BOX, ATOM_POLYTOPE};

use crate::monitor::AtomSet;
use crate::spec::{Coords, Matrix, SetDesc, Shape};

use crate::emit::{
    CertifiedBall, Child, FallbackLaw, ImageBuilder, PwaImageBuilder, PwaLaw, PwaLeaf, SegmentExit,
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
    /// The monitor of the current image (section 14) over an arena of `MonitorProgram::words` plus this
    /// many words (negative: too small); it lives until the next init of either kind.
    MonitorInit(i32),
    /// The monitor back to its first sample.
    MonitorReset,
    /// One monitor update with this state (at most 16 values, any values).
    MonitorUpdate(Vec<f32>),
}

/// One answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Answer {
    /// Whether the image was accepted.
    Init(bool),
    /// Status (wire value), the bits of the `MAX_M` input values, and the location of the row used
    /// (`Controller::location`, forced switching's discrete input).
    Step(u8, [u32; MAX_M], u8),
    /// The monitor's init: 0 accepted, 1 no monitor, 2 arena too small (3: another refusal, which Rust
    /// never gives), and the arena words the image's program needs (0 without one).
    MonitorInit(u8, u32),
    /// An update's report: the bits of lo and hi and the verdict's wire code (0xFF and zero bits without
    /// a monitor).
    Monitor(u32, u32, u8),
}

/// What a comparison found.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Comparison {
    /// Steps compared.
    pub states: usize,
    /// Steps whose status, an input bit or the location differed.
    pub mismatches: usize,
    /// Inits compared.
    pub inits: usize,
    /// Inits where one side accepted and the other refused.
    pub init_mismatches: usize,
    /// Steps per status wire value (`Ok`, `OutOfEnvelope`, `BadFrame`, `ImageRejected`), Rust side.
    pub by_status: [usize; 4],
    /// The first difference, described.
    pub first: Option<String>,
    /// Steps whose status agreed and whose inputs differed, but by no more than the ulps allowed
    /// ([`CHarness::compare_within`]; 0 for [`CHarness::compare`]).
    pub inexact: usize,
    /// The largest difference in ulps between the two sides' inputs on steps whose status agreed.
    pub ulp_max: u32,
    /// Monitor inits compared, and those whose outcome or arena words differed.
    pub monitor_inits: usize,
    pub monitor_init_mismatches: usize,
    /// Monitor traces compared (the updates after an accepted init or a reset, if any), and those with
    /// an update that differed.
    pub monitor_traces: usize,
    pub monitor_trace_mismatches: usize,
    /// Monitor updates compared (with a monitor), and those whose lo bits, hi bits or verdict differed.
    pub monitor_updates: usize,
    pub monitor_mismatches: usize,
    /// Updates per verdict (pending, satisfied, violated, boundary), Rust side.
    pub monitor_verdicts: [usize; 4],
    /// Traces per verdict of their last update, Rust side.
    pub monitor_decided: [usize; 4],
}

/// Distance in ulps between two f32 bit patterns, counted along the ordered line of floats: 0 for equal
/// bits, at least 1 for different bits (−0 and +0 are 1 apart), `u32::MAX` if one is NaN and the bits
/// differ.
pub fn ulp_distance(a: u32, b: u32) -> u32 {
    if a == b {
        return 0;
    }
    if f32::from_bits(a).is_nan() || f32::from_bits(b).is_nan() {
        return u32::MAX;
    }
    // Map the sign-magnitude bits onto a monotone integer line.
    let key = |x: u32| -> i64 {
        if x & 0x8000_0000 != 0 {
            -((x & 0x7FFF_FFFF) as i64)
        } else {
            x as i64
        }
    };
    u32::try_from((key(a) - key(b)).unsigned_abs())
        .unwrap_or(u32::MAX)
        .max(1)
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
            // <math.h>'s functions of model programs.
            .arg("-lm")
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
                Op::Step(x) | Op::MonitorUpdate(x) => {
                    let k = u8::try_from(x.len())
                        .ok()
                        .filter(|&k| k <= 16)
                        .ok_or_else(|| HarnessError::Driver("state longer than 16".into()))?;
                    input.push(if matches!(op, Op::Step(_)) {
                        b'S'
                    } else {
                        b'U'
                    });
                    input.push(k);
                    for v in x {
                        input.extend_from_slice(&v.to_le_bytes());
                    }
                }
                Op::MonitorInit(slack) => {
                    if *slack > 64 {
                        return Err(HarnessError::Driver("arena slack over 64 words".into()));
                    }
                    input.push(b'M');
                    input.extend_from_slice(&slack.to_le_bytes());
                }
                Op::MonitorReset => input.push(b'Z'),
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
            let mut take = |k: usize| -> Result<&[u8], HarnessError> {
                let (head, rest) = bytes
                    .split_at_checked(k)
                    .ok_or_else(|| HarnessError::Driver("short answer".into()))?;
                bytes = rest;
                Ok(head)
            };
            let word = |b: &[u8]| u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
            match op {
                Op::Reset | Op::MonitorReset => {}
                Op::MonitorInit(_) => {
                    let a = take(5)?;
                    answers.push(Answer::MonitorInit(a[0], word(&a[1..])));
                }
                Op::MonitorUpdate(_) => {
                    let a = take(9)?;
                    answers.push(Answer::Monitor(word(a), word(&a[4..]), a[8]));
                }
                Op::InitBytes(_) | Op::InitEmbedded => {
                    let a = take(1)?;
                    answers.push(Answer::Init(a[0] == 0));
                }
                Op::Step(_) => {
                    let rec = 1 + 4 * MAX_M + 1;
                    let head = take(rec)?;
                    let mut u = [0u32; MAX_M];
                    for (j, c) in head[1..rec - 1].chunks_exact(4).enumerate() {
                        u[j] = word(c);
                    }
                    answers.push(Answer::Step(head[0], u, head[rec - 1]));
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

    /// Runs `ops` through both and compares, bit for bit.
    pub fn compare(&self, ops: &[Op]) -> Result<Comparison, HarnessError> {
        self.compare_within(ops, 0)
    }

    /// Runs `ops` through both and compares: statuses and accepted images exactly, inputs within `ulps`
    /// ulps per component (the module doc says when that is needed).
    pub fn compare_within(&self, ops: &[Op], ulps: u32) -> Result<Comparison, HarnessError> {
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
        let starts = trace_starts(ops);
        // The monitor trace being compared: whether an update differed, and the last verdict (Rust).
        let mut trace: Option<(bool, u8)> = None;
        let finish = |out: &mut Comparison, t: Option<(bool, u8)>| {
            if let Some((differed, verdict)) = t {
                out.monitor_traces += 1;
                out.monitor_trace_mismatches += usize::from(differed);
                if let Some(k) = out.monitor_decided.get_mut(verdict as usize) {
                    *k += 1;
                }
            }
        };
        for (i, (a, b)) in c.iter().zip(&r).enumerate() {
            match (a, b) {
                (Answer::MonitorInit(ca, wa), Answer::MonitorInit(cb, wb)) => {
                    finish(&mut out, trace.take());
                    out.monitor_inits += 1;
                    if ca != cb || wa != wb {
                        out.monitor_init_mismatches += 1;
                        out.first.get_or_insert_with(|| {
                            format!(
                                "answer {i}: monitor init: C {ca} ({wa} words), Rust {cb} ({wb} words)"
                            )
                        });
                    }
                }
                (Answer::Monitor(la, ha, va), Answer::Monitor(lb, hb, vb)) => {
                    let differs = la != lb || ha != hb || va != vb;
                    if *vb == u8::MAX && !differs {
                        // No monitor on either side.
                        continue;
                    }
                    if starts.contains(&i) {
                        finish(&mut out, trace.take());
                        trace = Some((false, *vb));
                    }
                    out.monitor_updates += 1;
                    if let Some(k) = out.monitor_verdicts.get_mut(*vb as usize) {
                        *k += 1;
                    }
                    if differs {
                        out.monitor_mismatches += 1;
                        out.first.get_or_insert_with(|| {
                            format!(
                                "answer {i}: monitor update {}: C lo {:?} ({la:#010x}) hi {:?} ({ha:#010x}) verdict {va}, \
                                 Rust lo {:?} ({lb:#010x}) hi {:?} ({hb:#010x}) verdict {vb}",
                                out.monitor_updates - 1,
                                f32::from_bits(*la),
                                f32::from_bits(*ha),
                                f32::from_bits(*lb),
                                f32::from_bits(*hb),
                            )
                        });
                    }
                    if let Some(t) = trace.as_mut() {
                        t.0 |= differs;
                        t.1 = *vb;
                    }
                }
                (Answer::Init(x), Answer::Init(y)) => {
                    finish(&mut out, trace.take());
                    out.inits += 1;
                    if x != y {
                        out.init_mismatches += 1;
                        out.first.get_or_insert_with(|| {
                            format!("answer {i}: C accepted = {x}, Rust accepted = {y}")
                        });
                    }
                }
                (Answer::Step(sa, ua, la), Answer::Step(sb, ub, lb)) => {
                    out.states += 1;
                    if let Some(k) = out.by_status.get_mut(*sb as usize) {
                        *k += 1;
                    }
                    let d = ua
                        .iter()
                        .zip(ub)
                        .map(|(&a, &b)| ulp_distance(a, b))
                        .max()
                        .unwrap_or(0);
                    if sa == sb {
                        out.ulp_max = out.ulp_max.max(d);
                        if d > 0 && d <= ulps {
                            out.inexact += 1;
                        }
                    }
                    if sa != sb || d > ulps || la != lb {
                        out.mismatches += 1;
                        out.first.get_or_insert_with(|| {
                            format!(
                                "step {step} (answer {i}): C status {sa} u {:?} location {la}, Rust status {sb} u {:?} location {lb}",
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
        finish(&mut out, trace.take());
        Ok(out)
    }
}

/// The indices of the answers to `ops` that begin a monitor trace: the first update after a monitor init
/// or reset.
fn trace_starts(ops: &[Op]) -> BTreeSet<usize> {
    let mut starts = BTreeSet::new();
    let (mut answer, mut pending) = (0usize, false);
    for op in ops {
        match op {
            Op::Reset => continue,
            Op::MonitorReset => {
                pending = true;
                continue;
            }
            Op::MonitorInit(_) => pending = true,
            Op::InitBytes(_) | Op::InitEmbedded => pending = false,
            Op::MonitorUpdate(_) => {
                if pending {
                    starts.insert(answer);
                }
                pending = false;
            }
            Op::Step(_) => {}
        }
        answer += 1;
    }
    starts
}

/// The Rust side of [`reference`]: the controller, the last applied input and the answers so far.
struct Reference<'a> {
    ctl: Option<Controller<'a>>,
    applied: Input,
    answers: Vec<Answer>,
}

impl<'a> Reference<'a> {
    /// One op other than [`Op::MonitorInit`], with the monitor initialised since the last init, if any.
    fn apply(&mut self, image: &'a [u8], op: &'a Op, mon: Option<&mut Monitor<'_>>) {
        match op {
            Op::InitBytes(_) | Op::InitEmbedded => {
                let bytes: &[u8] = match op {
                    Op::InitBytes(b) => b,
                    _ => image,
                };
                self.ctl = decode(bytes).ok().map(Controller::new);
                self.applied = Input::zero(self.ctl.as_ref().map_or(0, |c| c.image().plant_m()));
                self.answers.push(Answer::Init(self.ctl.is_some()));
            }
            Op::Reset => {
                if let Some(c) = self.ctl.as_mut() {
                    c.reset();
                    self.applied = Input::zero(c.image().plant_m());
                }
            }
            Op::Step(x) => {
                let (status, u) = match self.ctl.as_mut() {
                    None => (Status::ImageRejected, Input::zero(0)),
                    Some(c) => match c.step_plant(x) {
                        Ok(u) => (Status::Ok, u),
                        Err(s) => (s, c.fallback(x, &self.applied)),
                    },
                };
                self.applied = u;
                let location = self.ctl.as_ref().map_or(0, |c| c.location() as u8);
                self.answers.push(Answer::Step(
                    status as u8,
                    u.values().map(f32::to_bits),
                    location,
                ));
            }
            Op::MonitorReset => {
                if let Some(m) = mon {
                    m.reset();
                }
            }
            Op::MonitorUpdate(x) => self.answers.push(match mon {
                Some(m) => {
                    let r = m.update(x);
                    Answer::Monitor(r.lo.to_bits(), r.hi.to_bits(), r.verdict as u8)
                }
                None => Answer::Monitor(0, 0, u8::MAX),
            }),
            Op::MonitorInit(_) => {}
        }
    }
}

/// The Rust evaluator's answers to `ops` (`InitEmbedded` uses `image`); the monitor's are
/// `shared_types::monitor::Monitor`'s, over an arena of exactly the words asked for.
pub fn reference(image: &[u8], ops: &[Op]) -> Vec<Answer> {
    let mut r = Reference {
        ctl: None,
        applied: Input::zero(0),
        answers: Vec::new(),
    };
    let mut i = 0usize;
    while let Some(op) = ops.get(i) {
        i += 1;
        let Op::MonitorInit(slack) = op else {
            r.apply(image, op, None);
            continue;
        };
        let prog: Option<MonitorProgram<'_>> = r.ctl.as_ref().and_then(|c| c.image().monitor());
        let words = prog.map_or(0, |p| p.words());
        let len = (words as i64 + i64::from(*slack)).max(0) as usize;
        let mut arena = vec![0u32; len];
        let mut mon = match prog {
            None => Err(1u8),
            Some(p) => Monitor::new(p, &mut arena).map_err(|_| 2u8),
        };
        r.answers.push(Answer::MonitorInit(
            mon.as_ref().err().copied().unwrap_or(0),
            words as u32,
        ));
        // The monitor lives until the next init of either kind.
        while let Some(op) = ops.get(i) {
            if matches!(op, Op::InitBytes(_) | Op::InitEmbedded | Op::MonitorInit(_)) {
                break;
            }
            r.apply(image, op, mon.as_mut().ok());
            i += 1;
        }
    }
    r.answers
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

/// A random trajectory of a feedforward image and a start at a random multiple ([`radius_factor`]) of its
/// ball's radius, in the metric of its first segment's location.
fn start_near_ball(image: &Image<'_>, rng: &mut ChaCha8Rng) -> (usize, Vec<f32>) {
    let n = image.n();
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
    let rho = radius_factor(rng);
    (t, point_at(rng, &c, delta * rho, norm))
}

/// The plant state whose ξ is `xi`, for an image with model maps made by [`maps_image`] (whose coords are
/// ξ_i = x_i + h_i(z), z the states past the first n): z drawn at random (its first component of order 1,
/// the others, which only the input map reads, at scales up to 10⁵ so that the functions' argument
/// reduction is exercised), x_i = ξ_i − h_i(z) with h(z) = coords(0, z) as the target computes it. `xi`
/// itself without model maps, or if it has another length than n (then z is appended, and the state
/// has a wrong length as `xi` had). For an image with controller states ([`ext_image`], whose coords are
/// ξ = (x, ζ)), the first `n_plant` components of `xi`.
fn lift(image: &Image<'_>, rng: &mut ChaCha8Rng, xi: Vec<f32>) -> Vec<f32> {
    let Some(maps) = image.model_maps() else {
        return xi;
    };
    let (n, np) = (image.n(), maps.n_plant());
    if maps.n_ext() > 0 {
        // An [`ext_image`]: ξ = (x, ζ), and ζ is the controller's, so the plant's state is the first
        // n_plant components.
        return if xi.len() == n {
            xi[..np.min(n)].to_vec()
        } else {
            xi
        };
    }
    let z: Vec<f32> = (n..np)
        .map(|k| {
            let scale = if k == n {
                1.0
            } else {
                [1.0, 1.0, 10.0, 1e3, 1e5][rng.random_range(0..5)]
            };
            (scale * normal(rng)) as f32
        })
        .collect();
    let mut probe = vec![0.0f32; np];
    probe[n..].copy_from_slice(&z);
    let mut h = vec![0.0f32; n];
    if xi.len() != n || maps.coords().eval(&probe, &mut h).is_err() {
        return xi.into_iter().chain(z).collect();
    }
    xi.iter()
        .zip(&h)
        .map(|(&a, &b)| (a as f64 - b as f64) as f32)
        .chain(z)
        .collect()
}

/// A seeded scenario of at least `states` steps for `image`, starting with [`Op::InitEmbedded`]. An image
/// with segment exits gets [`exits_scenario`]'s; an image with model maps ([`maps_image`]) gets the
/// feedforward one in ξ, each state lifted to a plant state ([`lift`]).
///
/// Feedforward: runs of steps from a reset, whose first state lies inside a ball, on its boundary (to a
/// few ulps) or outside it, continued past the trajectory's end (so the segment cursor, each location's
/// gain, the terminal behaviour and the out-of-envelope latch are exercised). PWA: states inside, on and
/// outside the certified balls (in their own whitened metric) and across the whole envelope's bounding
/// box. Both: about 2.5 % unusable or overflowing states.
pub fn scenario(image: &Image<'_>, seed: u64, states: usize) -> Vec<Op> {
    if image.has_exits() {
        return exits_scenario(image, seed, states).0;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = image.n();
    let mut ops = vec![Op::InitEmbedded];
    let mut count = 0usize;
    match image.mode() {
        Mode::Feedforward => {
            while count < states {
                ops.push(Op::Reset);
                let (t, x0) = start_near_ball(image, &mut rng);
                let len = image.trajectory_len(t) + rng.random_range(0..4);
                let len = if rng.random::<f64>() < 0.2 {
                    rng.random_range(1..=len)
                } else {
                    len
                };
                let mut x = x0;
                for _ in 0..len {
                    let plant = lift(image, &mut rng, x.clone());
                    ops.push(Op::Step(perturb(&mut rng, plant)));
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

/// What an [`exits_scenario`] exercised, as its own replica of the segment cursor (the logic of
/// `Controller::step_exits`, run in f32 on the states it emits) counted it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ExitCoverage {
    /// Guard exits taken.
    pub crossings: usize,
    /// The distinct samples (since their segment began) at which guard exits were taken.
    pub crossing_samples: BTreeSet<usize>,
    /// Table exits taken (a non-last segment's rows used up).
    pub table_moves: usize,
    /// Guard segments whose rows ran out before the guard was seen (the envelope is left).
    pub run_outs: usize,
    /// Of those, the ones at which the Rust evaluator indeed answered `OutOfEnvelope` (a check that the
    /// replica and the evaluator agree).
    pub run_outs_confirmed: usize,
    /// States placed one ulp (in one component) from a guard's threshold, on the side that takes the exit.
    pub at_threshold_taken: usize,
    /// The same, on the side that does not.
    pub at_threshold_not_taken: usize,
    /// States exactly at a threshold: fl(Σⱼ âⱼxⱼ) − b̂ = −θ in the f32 test (taken, `<=`; possible for the
    /// dyadic guards of [`exits_image`], whose arithmetic on a dyadic grid is exact).
    pub at_threshold_exact: usize,
}

/// fl(Σⱼ âⱼxⱼ) − b̂ in f32, as `Controller::step_exits` computes it.
fn guard_value(a: &[u8], b: f32, x: &[f32]) -> f32 {
    let mut acc = 0.0f32;
    for (c, &xi) in a.chunks_exact(4).zip(x) {
        acc += f32::from_le_bytes([c[0], c[1], c[2], c[3]]) * xi;
    }
    acc - b
}

/// `x` snapped to the grid 1/64 and its component of largest |âⱼ| solved for â·x − b̂ = −θ (in f64, then
/// f32); true if the f32 test then gives exactly −θ (`x` is changed only then).
fn place_exact(a: &[u8], b: f32, theta: f32, x: &mut [f32]) -> bool {
    let av: Vec<f64> = a
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
        .collect();
    let Some(j) = (0..av.len()).max_by(|&i, &k| av[i].abs().total_cmp(&av[k].abs())) else {
        return false;
    };
    if av[j] == 0.0 {
        return false;
    }
    let mut y: Vec<f32> = x.iter().map(|&v| (v * 64.0).round() / 64.0).collect();
    let rest: f64 = (0..av.len())
        .filter(|&i| i != j)
        .map(|i| av[i] * y[i] as f64)
        .sum();
    y[j] = ((b as f64 - theta as f64 - rest) / av[j]) as f32;
    let ok = guard_value(a, b, &y).to_bits() == (-theta).to_bits();
    if ok {
        x.copy_from_slice(&y);
    }
    ok
}

/// Whether a guard exit is taken at `x`: fl(Σⱼ âⱼxⱼ) − b̂ ≤ −θ, as `Controller::step_exits` computes it.
fn guard_taken(a: &[u8], b: f32, theta: f32, x: &[f32]) -> bool {
    guard_value(a, b, x) <= -theta
}

/// `x` moved along â so that â·x − b̂ = `target` (in f64, then rounded to f32); with `edge`, then moved
/// ulp by ulp in its component of largest |âⱼ| to the last value on the side `take` of the f32 test (the
/// neighbouring value is on the other side). Returns whether the guard test gives `take`.
fn place(a: &[u8], b: f32, theta: f32, x: &mut [f32], target: f64, edge: bool, take: bool) -> bool {
    let av: Vec<f64> = a
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
        .collect();
    let aa: f64 = av.iter().map(|v| v * v).sum();
    if aa > 0.0 {
        let g: f64 = av
            .iter()
            .zip(x.iter())
            .map(|(p, &q)| p * q as f64)
            .sum::<f64>()
            - b as f64;
        for (xi, ai) in x.iter_mut().zip(&av) {
            *xi = (*xi as f64 + (target - g) * ai / aa) as f32;
        }
    }
    if edge {
        let j = (0..av.len())
            .max_by(|&i, &k| av[i].abs().total_cmp(&av[k].abs()))
            .unwrap_or(0);
        let up = av[j] > 0.0;
        // `toward` lowers âⱼxⱼ (towards taking the exit), `away` raises it.
        let toward = |v: f32| if up { v.next_down() } else { v.next_up() };
        let away = |v: f32| if up { v.next_up() } else { v.next_down() };
        for _ in 0..4096 {
            if guard_taken(a, b, theta, x) {
                break;
            }
            x[j] = toward(x[j]);
        }
        for _ in 0..4096 {
            if !guard_taken(a, b, theta, x) {
                break;
            }
            x[j] = away(x[j]);
        }
        if take {
            x[j] = toward(x[j]);
        }
    }
    guard_taken(a, b, theta, x) == take
}

/// A seeded scenario for a feedforward image with segment exits, of at least `states` steps, starting with
/// [`Op::InitEmbedded`], and what it exercised.
///
/// Runs of steps from a reset, the first state inside, on or outside a ball. The scenario keeps its own
/// replica of the segment cursor; in a guard segment it plans the sample at which the guard is crossed (any
/// sample of the segment, or, one time in eight, none before its rows run out) and places each state on
/// the side of the guard the plan asks for: clearly (a random margin), or one ulp from the threshold of
/// the f32 test (one time in five before the crossing, one time in three at it, and at it, half of those
/// times, exactly on the threshold where the guard's arithmetic allows). Runs last the
/// trajectory's rows plus up to 5 samples (a fifth of them shorter), so table exits, the terminal
/// behaviour and the out-of-envelope latch are reached; about 2.5 % of the states are unusable or
/// overflowing, as in [`scenario`].
pub fn exits_scenario(image: &Image<'_>, seed: u64, states: usize) -> (Vec<Op>, ExitCoverage) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = image.n();
    let mut ops = vec![Op::InitEmbedded];
    let mut cov = ExitCoverage::default();
    let mut ctl = Controller::new(*image);
    let mut count = 0usize;
    while count < states {
        ops.push(Op::Reset);
        ctl.reset();
        let (t, mut w) = start_near_ball(image, &mut rng);
        let len = image.trajectory_len(t) + rng.random_range(0..6);
        let len = if rng.random::<f64>() < 0.2 {
            rng.random_range(1..=len)
        } else {
            len
        };
        // The replica: active trajectory, segment, κ at its start, κ; the planned crossing sample.
        let mut active: Option<(usize, usize, usize)> = None; // (trajectory, first segment, count)
        let (mut seg, mut seg_kappa, mut kappa) = (0usize, 0usize, 0usize);
        let mut latched = false;
        let mut plan: Option<usize> = None;
        for k in 0..len {
            let mut x = w.clone();
            // Place the state relative to the active guard (not at κ = 0: that state selects the ball).
            if let (Some((_, a0, cnt)), false, true) = (active, latched, k > 0) {
                if seg + 1 < a0 + cnt {
                    if let (Exit::Guard { a, b, theta, .. }, Some(g)) =
                        (image.exit(seg), image.segment(seg))
                    {
                        let dwell = *plan.get_or_insert_with(|| {
                            if rng.random::<f64>() < 0.125 {
                                g.len + rng.random_range(0..3)
                            } else {
                                rng.random_range(0..g.len)
                            }
                        });
                        let local = kappa - seg_kappa;
                        let take = local >= dwell;
                        let margin = 0.3 * normal(&mut rng).abs() + 1e-3;
                        let target = if take {
                            -(theta as f64) - margin
                        } else {
                            -(theta as f64) + margin
                        };
                        let edge = rng.random::<f64>() < if take { 1.0 / 3.0 } else { 0.2 };
                        if take && edge && rng.random::<bool>() && place_exact(a, b, theta, &mut x)
                        {
                            cov.at_threshold_exact += 1;
                        } else if place(a, b, theta, &mut x, target, edge, take) && edge {
                            if take {
                                cov.at_threshold_taken += 1;
                            } else {
                                cov.at_threshold_not_taken += 1;
                            }
                        }
                    }
                }
            }
            let x = perturb(&mut rng, x);
            let result = ctl.step(&x);
            ops.push(Op::Step(x.clone()));
            count += 1;
            for v in w.iter_mut() {
                *v += (0.05 * normal(&mut rng)) as f32;
            }
            // The replica of `Controller::step_exits` on this state.
            if x.len() != n || !x.iter().all(|v| v.is_finite()) || latched {
                continue;
            }
            if active.is_none() {
                match ctl.active_trajectory() {
                    Some(tr) => {
                        let (a0, cnt) = image.trajectory_segments(tr as usize);
                        active = Some((tr as usize, a0, cnt));
                        seg = a0;
                    }
                    None => {
                        latched = true;
                        continue;
                    }
                }
            }
            let Some((_, a0, cnt)) = active else { continue };
            let last = a0 + cnt - 1;
            for _ in 0..cnt {
                let Some(g) = image.segment(seg) else { break };
                if seg >= last {
                    break;
                }
                match image.exit(seg) {
                    Exit::Guard { a, b, theta, .. } => {
                        if guard_taken(a, b, theta, &x) {
                            cov.crossings += 1;
                            cov.crossing_samples.insert(kappa - seg_kappa);
                            seg += 1;
                            seg_kappa = kappa;
                            plan = None;
                            continue;
                        }
                    }
                    Exit::Table => {
                        if kappa - seg_kappa >= g.len {
                            cov.table_moves += 1;
                            seg += 1;
                            seg_kappa += g.len;
                            plan = None;
                            continue;
                        }
                    }
                }
                break;
            }
            if let Some(g) = image.segment(seg) {
                if kappa - seg_kappa >= g.len && seg < last {
                    cov.run_outs += 1;
                    latched = true;
                    if result == Err(Status::OutOfEnvelope) {
                        cov.run_outs_confirmed += 1;
                    }
                    continue;
                }
            }
            if result.is_ok() {
                kappa += 1;
            }
        }
    }
    (ops, cov)
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

/// A seeded synthetic feedforward image with segment exits: `locations` locations (1 to 3: with one, every
/// trajectory is one segment with a table exit), `trajectories` balls, each trajectory 2 or 3 segments
/// of 3 to 12 rows (one with a single location) whose non-last segments end at a guard (three in four;
/// θ = 0 one time in four, else up to 0.3; one guard in three dyadic: âⱼ = ±2^k, k ∈ −2..=1, b̂ and θ
/// multiples of 1/16, so that states exactly on its threshold exist) or with their table; terminal behaviour and fallback law (index)
/// as in [`feedforward_image`], input box `[-1, 1]^m`.
#[allow(clippy::too_many_arguments)]
pub fn exits_image(
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
    let f32s = |rng: &mut ChaCha8Rng, k: usize, scale: f64| -> Vec<f32> {
        (0..k).map(|_| (scale * normal(rng)) as f32).collect()
    };
    for _ in 0..trajectories {
        let segments = if locations > 1 {
            rng.random_range(2..=3)
        } else {
            1
        };
        let mut location = Vec::new();
        let mut exits = Vec::new();
        let mut l = rng.random_range(0..locations);
        for s in 0..segments {
            if s > 0 {
                l = (l + rng.random_range(1..locations)) % locations;
            }
            let len = rng.random_range(3..=12);
            location.extend(std::iter::repeat_n(l as u8, len));
            exits.push(if s + 1 < segments && rng.random::<f64>() < 0.75 {
                let theta = if rng.random::<f64>() < 0.25 {
                    0.0
                } else {
                    rng.random_range(0.0..0.3) as f32
                };
                if rng.random::<f64>() < 1.0 / 3.0 {
                    let a = (0..n)
                        .map(|_| {
                            let p = 2f32.powi(rng.random_range(-2..=1));
                            if rng.random::<bool>() {
                                p
                            } else {
                                -p
                            }
                        })
                        .collect();
                    SegmentExit::Guard {
                        a,
                        b: (8.0 * normal(&mut rng)).round() as f32 / 16.0,
                        theta: rng.random_range(0..5) as f32 / 16.0,
                        next: f32s(&mut rng, n, 1.0),
                    }
                } else {
                    SegmentExit::Guard {
                        a: f32s(&mut rng, n, 1.0),
                        b: (0.5 * normal(&mut rng)) as f32,
                        theta,
                        next: f32s(&mut rng, n, 1.0),
                    }
                }
            } else {
                SegmentExit::Table
            });
        }
        let rows = location.len();
        b.add_trajectory(TrajectoryEntry {
            x0: random_vec(&mut rng, n, 1.0),
            delta: rng.random_range(0.3..2.0),
            v: random_vec(&mut rng, rows * m, 0.5),
            location,
        });
        b.exits.push(exits);
    }
    b.fallback = fallback_law(&mut rng, fallback, n, m);
    b.input_box = Some((vec![-1.0; m], vec![1.0; m]));
    b.terminal = terminal;
    b.to_bytes()
        .expect("a valid synthetic image with segment exits")
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

/// A seeded synthetic feedforward image with model maps (`shared_types::maps`): the law of a one-location
/// [`feedforward_image`] in ξ (dims n, m, `trajectories` balls, the given terminal behaviour), a plant of
/// `n_plant ≥ n + 1` states and `m_plant` inputs, the fallback `fallback` in the plant's input space (0
/// hold, 1 zero, 3 constant) with the input box `[-1, 1]^m_plant`, and the maps compiled from expressions
/// with `crate::expr`:
/// * coords: ξ_i = x_i + h(z₀) with h(z) = 0.25·z² − z/(2 + z²) + 0.5·(1 + z²)^−1 − (−z)·0.125 and z₀ the
///   state after the first n (arithmetic only; [`lift`] inverts it);
/// * input_map, `transcendental = false`: u_j = w_(j mod m)·(1 + 0.5·x_a²)^−1 − 0.25·x_b/(3 + x_a²)
///   (arithmetic only: the C and Rust sides agree bit for bit);
/// * input_map, `transcendental = true`: u_j = F(x_a)·w_(j mod m) with F the j-th (from `first_func`) of
///   sin, cos, tan, exp(0.5·), log(1 + ·²), sqrt(1 + ·²), abs, atan, tanh, atan2(·, 1 + x_b²): one
///   library call per output, multiplied, so that a difference of the two sides' libraries shows as
///   about the same number of ulps in u.
///
/// Here x_a, x_b are plant states past the first n + 1 when there are some (free of coords), else z₀.
#[allow(clippy::too_many_arguments)]
pub fn maps_image(
    seed: u64,
    n_plant: usize,
    m_plant: usize,
    n: usize,
    m: usize,
    trajectories: usize,
    terminal: Terminal,
    fallback: usize,
    transcendental: bool,
    first_func: usize,
) -> Vec<u8> {
    use crate::emit::ModelMapsSpec;
    use crate::expr::{compile::compile, parse, Names};
    assert!(n_plant > n, "maps_image needs a state past the first n");
    let base = feedforward_image(seed, n, m, 1, trajectories, terminal, 1);
    let img = decode(&base).expect("feedforward_image is valid");
    let mut b = ImageBuilder::from_image(&img);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6d61_7073);
    b.fallback = fallback_law(&mut rng, fallback, n_plant, m_plant);
    b.input_box = Some((vec![-1.0; m_plant], vec![1.0; m_plant]));
    let names = Names {
        states: (0..n_plant).map(|i| format!("x{i}")).collect(),
        inputs: (0..m).map(|j| format!("w{j}")).collect(),
        params: vec![],
    };
    let z = format!("x{n}");
    let h = format!("(0.25*{z}^2 - {z}/(2 + {z}^2) + 0.5*(1 + {z}^2)^(-1) - (-{z})*0.125)");
    let coords: Vec<String> = (0..n).map(|i| format!("x{i} + {h}")).collect();
    let free = |k: usize| {
        if n_plant > n + 1 {
            format!("x{}", n + 1 + k % (n_plant - n - 1))
        } else {
            z.clone()
        }
    };
    let input_map: Vec<String> = (0..m_plant)
        .map(|j| {
            let (xa, xb, w) = (free(j), free(j + 1), format!("w{}", j % m));
            if transcendental {
                let f = match (first_func + j) % 10 {
                    0 => format!("sin({xa})"),
                    1 => format!("cos({xa})"),
                    2 => format!("tan({xa})"),
                    3 => format!("exp(0.5*{xa})"),
                    4 => format!("log(1 + {xa}^2)"),
                    5 => format!("sqrt(1 + {xa}^2)"),
                    6 => format!("abs({xa})"),
                    7 => format!("atan({xa})"),
                    8 => format!("tanh({xa})"),
                    _ => format!("atan2({xa}, 1 + {xb}^2)"),
                };
                format!("{f}*{w}")
            } else {
                format!("{w}*(1 + 0.5*{xa}^2)^(-1) - 0.25*{xb}/(3 + {xa}^2)")
            }
        })
        .collect();
    let program = |texts: &[String], inputs: usize| {
        let exprs: Vec<_> = texts
            .iter()
            .map(|t| parse(t, &names).expect("the harness's expressions parse"))
            .collect();
        compile(&exprs, n_plant, inputs, &[])
            .expect("the harness's expressions compile")
            .bytes
    };
    b.model_maps(ModelMapsSpec {
        n_plant,
        m_plant,
        ext_init: Vec::new(),
        coords: program(&coords, 0),
        input_map: program(&input_map, m),
    });
    b.to_bytes().expect("maps_image is valid")
}

/// A seeded synthetic feedforward image with model maps whose controller keeps states of its own (a
/// dynamic extension, `n_ext = 2`): a double integrator (x = (p, v), `n_plant = 2`) whose input, like a
/// flat plant's thrust, is a controller state, u = ζ0, with ζ̇0 = ζ1 and ζ̇1 = w (the law's input, m =
/// 1). The law is a one-location [`feedforward_image`] in ξ = (x, ζ) (n = 4, `trajectories` balls, the
/// given terminal behaviour) whose balls are all centred at ζ = ζ0 in their last two components, ζ0 the
/// stored initial values; the fallback `fallback` (0 hold, 1 zero, 3 constant) with the input box
/// `[-1, 1]`; the maps compiled from expressions with `crate::expr`:
/// * coords: ξ = (x0, x1, ζ0, ζ1);
/// * input_map: u = ζ0, ζ0⁺ = ζ0 + h·ζ1 + h²/2·w0, ζ1⁺ = ζ1 + h·w0 (the exact ZOH of the chain over the
///   period h), arithmetic only (the C and Rust sides agree bit for bit).
pub fn ext_image(seed: u64, trajectories: usize, terminal: Terminal, fallback: usize) -> Vec<u8> {
    use crate::emit::ModelMapsSpec;
    use crate::expr::{compile::compile, parse, Names};
    let (n_plant, m_plant, n_ext, n, m) = (2, 1, 2, 4, 1);
    let base = feedforward_image(seed, n, m, 1, trajectories, terminal, 1);
    let img = decode(&base).expect("feedforward_image is valid");
    let mut b = ImageBuilder::from_image(&img);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7a65_7461);
    let ext_init: Vec<f32> = (0..n_ext).map(|_| rng.random_range(-0.5f32..0.5)).collect();
    for t in &mut b.trajectories {
        for (c, &z) in t.x0[n_plant..].iter_mut().zip(&ext_init) {
            *c = z as f64;
        }
    }
    b.fallback = fallback_law(&mut rng, fallback, n_plant, m_plant);
    b.input_box = Some((vec![-1.0; m_plant], vec![1.0; m_plant]));
    let h = b.period;
    let names = Names {
        states: vec!["x0".into(), "x1".into(), "z0".into(), "z1".into()],
        inputs: vec!["w0".into()],
        params: vec![],
    };
    let program = |texts: &[String], inputs: usize| {
        let exprs: Vec<_> = texts
            .iter()
            .map(|t| parse(t, &names).expect("the harness's expressions parse"))
            .collect();
        compile(&exprs, n_plant + n_ext, inputs, &[])
            .expect("the harness's expressions compile")
            .bytes
    };
    let coords: Vec<String> = ["x0", "x1", "z0", "z1"].map(String::from).to_vec();
    let input_map = vec![
        "z0".to_string(),
        format!("z0 + {h}*z1 + {}*w0", h * h / 2.0),
        format!("z1 + {h}*w0"),
    ];
    b.model_maps(ModelMapsSpec {
        n_plant,
        m_plant,
        ext_init,
        coords: program(&coords, 0),
        input_map: program(&input_map, m),
    });
    b.to_bytes().expect("ext_image is valid")
}

/// `image` (feedforward without model maps, or PWA) with a seeded synthetic terminal law (section 11):
/// its ellipsoid centred on the first ball's centre with a random metric and acceptance radius, so that
/// the scenarios of [`scenario`] step in, out of and across it (the handover, the terminal phase and its
/// out-of-envelope answers).
pub fn with_terminal_law(image: &[u8], seed: u64) -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let img = decode(image).expect("a valid image");
    let (n, m) = (img.n(), img.m());
    let centre: Vec<f64> = if img.mode() == Mode::Feedforward {
        (0..n).map(|i| img.centre(0, i) as f64).collect()
    } else {
        (0..n).map(|i| img.ball_centre(0, i) as f64).collect()
    };
    let law = crate::certify::terminal::StoredTerminal {
        x_e: centre.iter().map(|c| (*c as f32) as f64).collect(),
        K: faer::Mat::from_fn(m, n, |_, _| (normal(&mut rng) as f32) as f64),
        v: random_vec(&mut rng, m, 0.5),
        P: {
            let p = random_spd(&mut rng, n);
            faer::Mat::from_fn(n, n, |i, j| p[i * n + j])
        },
        radius: rng.random_range(0.3f32..1.5),
    };
    if img.mode() == Mode::Feedforward {
        let mut b = ImageBuilder::from_image(&img);
        b.terminal_law = Some(law);
        b.to_bytes().expect("a valid image with a terminal law")
    } else {
        let mut b = PwaImageBuilder::from_image(&img).expect("a PWA image");
        b.terminal_law = Some(law);
        b.to_bytes().expect("a valid PWA image with a terminal law")
    }
}

// ---------------------------------------------------------------------------------------------------------
// Monitor traces.

/// One atom of a monitor program as its section stores it: kind, the state coordinates it reads, rows (a
/// polytope's; 0 otherwise) and its values.
#[derive(Clone, Debug)]
struct AtomRecord {
    kind: u32,
    idx: Vec<usize>,
    rows: usize,
    vals: Vec<f32>,
}

/// The atoms of a validated program, read from its section body (`shared_types::monitor`'s layout).
fn atom_records(prog: &MonitorProgram<'_>) -> Vec<AtomRecord> {
    let b = prog.body();
    let w = |i: usize| {
        b.get(4 * i..4 * i + 4)
            .map_or(0, |c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
    };
    let mut at = 5;
    (0..prog.atoms())
        .map(|_| {
            let (kind, d) = (w(at), w(at + 1) as usize);
            let idx = (0..d).map(|j| w(at + 2 + j) as usize).collect();
            let poly = kind == ATOM_POLYTOPE;
            let rows = if poly { w(at + 2 + d) as usize } else { 0 };
            let len = match kind {
                ATOM_BOX => 2 + 3 * d,
                ATOM_POLYTOPE => 3 + d + rows * d + rows,
                _ => 2 + 2 * d + 1,
            };
            let from = at + 2 + d + usize::from(poly);
            let vals = (from..at + len).map(|j| f32::from_bits(w(j))).collect();
            at += len;
            AtomRecord {
                kind,
                idx,
                rows,
                vals,
            }
        })
        .collect()
}

/// A point of an atom's coordinates: with `exact`, on its set's boundary as the f32 arithmetic sees it
/// where the kind allows (a box's face, exactly; a half-space's or a polytope row's plane and a ball's
/// sphere, to rounding); otherwise inside or outside, at a random depth.
fn atom_point(rng: &mut ChaCha8Rng, a: &AtomRecord, exact: bool) -> Vec<f64> {
    let d = a.idx.len();
    let v = |j: usize| a.vals.get(j).copied().unwrap_or(0.0) as f64;
    match a.kind {
        ATOM_BOX => {
            let mut y: Vec<f64> = (0..d)
                .map(|j| {
                    let (lo, hi) = (v(j), v(d + j));
                    let u: f64 = rng.random_range(-0.3..1.3);
                    lo + (hi - lo) * u
                })
                .collect();
            if exact {
                let j = rng.random_range(0..d);
                y[j] = if rng.random::<bool>() { v(j) } else { v(d + j) };
            }
            y
        }
        ATOM_BALL => {
            let e: Vec<f64> = (0..d).map(|_| normal(rng)).collect();
            let q = e.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300);
            let rho = if exact {
                1.0
            } else {
                rng.random_range(0.0..1.6)
            };
            (0..d).map(|j| v(j) + v(d) * rho * e[j] / q).collect()
        }
        _ => {
            // A half-space's plane, or a polytope row's (‖a‖ = 1 as the host stores them).
            let (a0, b) = if a.kind == ATOM_POLYTOPE {
                let r = rng.random_range(0..a.rows.max(1));
                (r * d, v(a.rows * d + r))
            } else {
                (0, v(d))
            };
            let off = if exact { 0.0 } else { 0.4 * normal(rng) };
            (0..d).map(|j| (b + off) * v(a0 + j)).collect()
        }
    }
}

/// A base path of `len` states for the monitor `prog` over a plant of `n` states: from a random start,
/// piecewise linear through 2 to 5 waypoints at random samples, each placing the coordinates of a random
/// atom at a point of its set ([`atom_point`]: inside, outside, or, three times in ten, on its boundary),
/// the other coordinates kept; with no noise (half the paths, so the waypoints are met exactly) or a
/// little.
pub fn anchor_path(
    prog: &MonitorProgram<'_>,
    n: usize,
    rng: &mut ChaCha8Rng,
    len: usize,
) -> Vec<Vec<f32>> {
    let atoms = atom_records(prog);
    let start: Vec<f64> = (0..n).map(|_| normal(rng)).collect();
    let mut way: Vec<(usize, Vec<f64>)> = vec![(0, start)];
    let mut times: Vec<usize> = (0..rng.random_range(2..=5))
        .map(|_| rng.random_range(0..len.max(1)))
        .collect();
    times.sort_unstable();
    for t in times {
        let mut p = way.last().map(|w| w.1.clone()).unwrap_or_default();
        if let Some(a) = atoms.get(rng.random_range(0..atoms.len().max(1))) {
            let exact = rng.random_bool(0.3);
            let y = atom_point(rng, a, exact);
            for (&c, v) in a.idx.iter().zip(y) {
                if let Some(slot) = p.get_mut(c) {
                    *slot = v;
                }
            }
        }
        way.push((t, p));
    }
    let noise = [0.0, 0.0, 0.003, 0.05][rng.random_range(0..4)];
    (0..len)
        .map(|t| {
            let i = way.iter().rposition(|w| w.0 <= t).unwrap_or(0);
            let (t0, p0) = &way[i];
            let x: Vec<f64> = match way.get(i + 1) {
                Some((t1, p1)) => {
                    let s = (t - t0) as f64 / (t1 - t0) as f64;
                    p0.iter().zip(p1).map(|(a, b)| a + s * (b - a)).collect()
                }
                None => p0.clone(),
            };
            x.iter().map(|v| (v + noise * normal(rng)) as f32).collect()
        })
        .collect()
}

/// With probability `rate`, an unusual state instead of `x`: NaN, +∞ or −∞ in one component, a mix of
/// them in several or in every one, every component NaN, a huge component (±3·10³⁸, whose squares overflow), or the
/// wrong number of values (shorter: the missing coordinates read as 0; longer; none).
pub fn perturb_monitor_state(rng: &mut ChaCha8Rng, x: Vec<f32>, rate: f64) -> Vec<f32> {
    if x.is_empty() || !rng.random_bool(rate) {
        return x;
    }
    let n = x.len();
    let mut y = x;
    let special = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
    match rng.random_range(0..9) {
        0..=2 => {
            let k = rng.random_range(0..3);
            y[rng.random_range(0..n)] = special[k];
        }
        3 => {
            for _ in 0..rng.random_range(2..=3) {
                y[rng.random_range(0..n)] = special[rng.random_range(0..3)];
            }
        }
        4 => {
            // Every component NaN, or each NaN, ±∞ or kept (so that NaNs of both signs meet: an atom's
            // inf − inf or 0·inf is a NaN of the other sign than the input's).
            let all = rng.random::<bool>();
            for v in y.iter_mut() {
                *v = if all {
                    f32::NAN
                } else {
                    [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, *v][rng.random_range(0..4)]
                };
            }
        }
        5 => {
            let s = if rng.random::<bool>() {
                3.0e38
            } else {
                -3.0e38
            };
            y[rng.random_range(0..n)] = s;
        }
        6 => y.truncate(rng.random_range(0..n)),
        7 => {
            while y.len() < 16 && rng.random_bool(0.7) {
                y.push(normal(rng) as f32);
            }
        }
        _ => y.clear(),
    }
    y
}

/// A base path generator for [`monitor_scenario`]: the trace's `len` states from its random source.
pub type MonitorPath<'p> = &'p dyn Fn(&mut ChaCha8Rng, usize) -> Vec<Vec<f32>>;

/// A seeded scenario for the task's monitor of `image` (which must carry one, section 14):
/// [`Op::InitEmbedded`], an [`Op::MonitorInit`] with one word too few (refused) and one with exactly the
/// program's words, then `traces` traces, each after an [`Op::MonitorReset`] (one time in twenty a new
/// init with 0 to 3 spare words) but the first. A trace has N + 1 to N + 4 updates (past N the report
/// stays; one in ten is cut short at random), its states from `path` or, without one, [`anchor_path`];
/// half the traces clean, the others with 1 %, 5 % or 30 % of their states perturbed
/// ([`perturb_monitor_state`]).
pub fn monitor_scenario(
    image: &Image<'_>,
    seed: u64,
    traces: usize,
    path: Option<MonitorPath<'_>>,
) -> Vec<Op> {
    let prog = image.monitor().expect("an image with a monitor");
    let n = image.plant_n();
    let horizon = prog.horizon();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut ops = vec![Op::InitEmbedded, Op::MonitorInit(-1), Op::MonitorInit(0)];
    for k in 0..traces {
        if k > 0 {
            ops.push(if rng.random_bool(0.05) {
                Op::MonitorInit(rng.random_range(0..=3))
            } else {
                Op::MonitorReset
            });
        }
        let len = horizon + 1 + rng.random_range(0..=3);
        let len = if rng.random_bool(0.1) {
            rng.random_range(1..=len)
        } else {
            len
        };
        let base = match path {
            Some(p) => p(&mut rng, len),
            None => anchor_path(&prog, n, &mut rng, len),
        };
        let rate = if rng.random::<bool>() {
            0.0
        } else {
            [0.01, 0.05, 0.3][rng.random_range(0..3)]
        };
        for x in base {
            ops.push(Op::MonitorUpdate(perturb_monitor_state(&mut rng, x, rate)));
        }
    }
    ops
}

/// The sets of the synthetic monitor programs, over a plant of 3 states: one of every atom kind (a box
/// over two coordinates, a ball over all three, a polytope by three rows over two, a half-space) and an
/// `Unsafe` union of a box and a ball (so its negation is an ∧ of negated atoms), all on dyadic values
/// (their faces are met exactly by dyadic states).
pub fn monitor_sets() -> Vec<(String, AtomSet)> {
    let set = |shape: Shape, coords: Coords| SetDesc { shape, coords };
    vec![
        (
            "B".into(),
            AtomSet::Set(set(
                Shape::Box {
                    lo: vec![-1.0, -0.5],
                    hi: vec![0.5, 1.0],
                },
                Coords::StateIndices(vec![0, 1]),
            )),
        ),
        (
            "S".into(),
            AtomSet::Set(set(
                Shape::Ball {
                    center: vec![0.5, 0.0, -0.5],
                    radius: 0.75,
                },
                Coords::State,
            )),
        ),
        (
            "P".into(),
            AtomSet::Set(set(
                Shape::Polytope {
                    A: Matrix {
                        rows: 3,
                        cols: 2,
                        data: vec![1.0, 0.0, -1.0, 1.0, 0.0, -1.0],
                    },
                    b: vec![1.0, 0.5, 0.75],
                },
                Coords::StateIndices(vec![1, 2]),
            )),
        ),
        (
            "H".into(),
            AtomSet::HalfSpace {
                a: vec![1.0, -1.0, 0.5],
                b: 0.25,
            },
        ),
        (
            "Unsafe".into(),
            AtomSet::Union(vec![
                set(
                    Shape::Box {
                        lo: vec![1.0],
                        hi: vec![2.0],
                    },
                    Coords::StateIndices(vec![2]),
                ),
                set(
                    Shape::Ball {
                        center: vec![-1.0, 1.0],
                        radius: 0.5,
                    },
                    Coords::StateIndices(vec![0, 2]),
                ),
            ]),
        ),
    ]
}

/// The synthetic monitor programs (formula, horizon N in samples; windows in samples, h = 1): every
/// operator (F, G, U, R with a = 0 and a > 0, windows of b ≤ 1 where U and R read no φ, an unbounded
/// window, an empty one past N), ∧ and ∨ (and →), negated atoms and a negated union, an atom
/// alone at the root, nested windows that exceed N, so the end-of-trace flush decides them, and ∧ and ∨
/// of atoms that are NaN on states with NaN or infinite components (a ball's NaN has the input's sign, a
/// half-space's or a polytope's inf − inf the other one).
pub const MONITOR_FORMULAS: [(&str, usize); 19] = [
    ("F[0,4] B & G[2,6] !S", 12),
    ("(B U[0,5] S) | (H R[2,7] !P)", 15),
    ("G[0,8] F[1,5] (S & !Unsafe)", 10),
    ("!Unsafe U (B & F[0,3] H)", 20),
    ("(S R[0,4] B) & (P U[3,9] !H)", 14),
    ("F[0,20] G[0,20] (B | H)", 25),
    ("G (F[0,3] S -> G[1,2] !P)", 16),
    (
        "(true U[0,3] P) & (false R[1,1] B) & (S U[1,1] H) & (P R[0,1] !B)",
        8,
    ),
    ("F[0,0] B | G[0,1] S | F[1,1] !H", 6),
    ("F[50,60] B | G[40,41] S", 30),
    ("S", 5),
    ("!H", 5),
    ("P & !B", 7),
    ("F[0,2] G[0,2] F[1,3] (B U[0,4] (S R[0,3] H))", 12),
    ("(!Unsafe U[2,9] (P | S)) R[1,6] (B -> F[0,4] !H)", 18),
    ("G[0,30] (B | F[0,5] S) & F[3,40] (P & G[0,6] !Unsafe)", 36),
    ("!(F[0,3] B) | (H U[2,2] S)", 9),
    ("G !Unsafe & F[0,4] (B & F[0,5] (S & F[0,5] H))", 12),
    ("(S & H) | (P & !S)", 3),
];

/// `image` (of a plant of 3 states) with the monitor of `formula` over [`monitor_sets`] (windows in
/// samples, h = 1) and horizon N = `horizon` samples (section 14).
pub fn monitor_image(image: &[u8], formula: &str, horizon: usize) -> Vec<u8> {
    let expr = crate::robustness::mtl::parse(formula).expect("the formula parses");
    let prog = crate::monitor::Program::compile(&expr, &monitor_sets(), 3, 1.0, horizon)
        .expect("the formula compiles");
    crate::monitor::attach(image, &prog.encode()).expect("the program attaches")
}

/// A run of `len` samples of the planar vehicle of `examples/planar-vehicle-waypoints.toml` (period
/// 0.01 s): from Init through W1 (reached by a random sample around the 2 s deadline), over the obstacle
/// (or, one time in five, straight through it), through W2 (within about its 2.5 s) and into Goal (within
/// about its 2.5 s), each aimed at a random point within 0.2 to 1.4 times the set's radius, then held
/// with a jitter; positions with a little noise, velocities their differences.
pub fn planar_waypoints_run(rng: &mut ChaCha8Rng, len: usize) -> Vec<Vec<f32>> {
    let aim = |rng: &mut ChaCha8Rng, c: [f64; 2], r: f64| {
        let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let rho = r * rng.random_range(0.2..1.4);
        [c[0] + rho * a.cos(), c[1] + rho * a.sin()]
    };
    let start = [rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2)];
    let t1 = rng.random_range(60..230usize);
    let t2 = t1 + rng.random_range(80..280usize);
    let t3 = t2 + rng.random_range(50..280usize);
    let mut way = vec![(0usize, start), (t1, aim(rng, [0.5, 1.0], 0.25))];
    if rng.random_bool(0.8) {
        way.push(((t1 + t2) / 2, [1.0, rng.random_range(1.35..1.7)]));
    }
    way.push((t2, aim(rng, [3.0, 0.9], 0.3)));
    way.push((t3, aim(rng, [2.0, 0.0], 0.1)));
    let noise = [0.0, 0.001, 0.01][rng.random_range(0..3)];
    let mut prev: Option<[f64; 2]> = None;
    (0..len)
        .map(|t| {
            let i = way.iter().rposition(|w| w.0 <= t).unwrap_or(0);
            let (t0, p0) = way[i];
            let p = match way.get(i + 1) {
                Some(&(t1, p1)) => {
                    let s = (t - t0) as f64 / (t1 - t0) as f64;
                    [p0[0] + s * (p1[0] - p0[0]), p0[1] + s * (p1[1] - p0[1])]
                }
                None => p0,
            };
            let p = [
                p[0] + noise * rng.random_range(-1.0..1.0),
                p[1] + noise * rng.random_range(-1.0..1.0),
            ];
            let v = prev.map_or([0.0, 1.0], |q| [(p[0] - q[0]) / 0.01, (p[1] - q[1]) / 0.01]);
            prev = Some(p);
            vec![p[0] as f32, p[1] as f32, v[0] as f32, v[1] as f32]
        })
        .collect()
}

/// A run of `len` samples of `examples/double-integrator.toml` (x⁺ = A x + B u, period 0.1 s) from Init
/// under a saturated PD law towards a target near Goal's centre, with random gains and input bound (up to
/// 3, past the spec's 1, so that the velocity sometimes exceeds Unsafe's 1.5).
pub fn double_integrator_run(rng: &mut ChaCha8Rng, len: usize) -> Vec<Vec<f32>> {
    let (kp, kd) = (rng.random_range(0.3..6.0), rng.random_range(0.3..4.0));
    let umax = [1.0, 1.0, 2.0, 3.0][rng.random_range(0..4)];
    let target = 1.0 + rng.random_range(-0.08..0.08);
    let mut x = [rng.random_range(-0.1..0.1), 0.0f64];
    (0..len)
        .map(|_| {
            let s = vec![x[0] as f32, x[1] as f32];
            let u = (kp * (target - x[0]) - kd * x[1]).clamp(-umax, umax);
            x = [x[0] + 0.1 * x[1] + 0.005 * u, x[1] + 0.1 * u];
            s
        })
        .collect()
}
