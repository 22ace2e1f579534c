//! `host-compiler inspect IMAGE [--json]`: decode and validate a controller image with the same decoder the
//! firmware runs, then print its whole content (header, K, P, balls, tables, fallback, terminal, CRC,
//! size) as JSON, or as a readable summary. A rejected image is reported with what is wrong with it.
//!
//! For a PWA-feedback image (Ch. 6) the content is the laws `u = K_j x + θ0_j` (with `θ_j = K_j − K` when
//! the image has one location), the point-location tree (depth, nodes with their hyperplanes and
//! children), the leaves (partition and certified balls), the ball table (centre, whitened centre, stored
//! radius), the factors R̂ of the whitened ball test, and the worst-case work of one control step for this
//! image.
//!
//! For an image with model maps (a feedback-linearizable plant, `shared_types::maps`) it adds the plant's
//! dimensions and, per program (`coords`, `input_map`), its length, slots, outputs, constants, code length
//! and stack depth; the fallback and the input box are then shown in the plant's input space.
//!
//! # For independent checkers
//! With `--json` it also shows, under `"certificate"`, what an independent checker needs that the image
//! does not store, read from the certificate `synth` wrote (`--certificate FILE`, by default
//! `certificate.json` beside the image when there is one): the certified f64 δ, the f64 K and P (per
//! location for a hybrid image), the Goal step of every trajectory, its nominal states and the f32
//! rounding bound ε̄, and for a PWA image each ball's provenance (trajectory, κ) and its successor. The
//! certificate must be this image's: `synth` records the image's SHA-256 in it (`"image"`), and a
//! certificate of other bytes is refused (exit 2, naming both files). Without one, `"certificate"` says
//! which items are missing and why.
#![allow(non_snake_case)]

use std::fmt::Write as _;
use std::io::Write as _;

use serde::Serialize;
use shared_types::image::{
    decode, directory, Fallback, Header, Image, ImageError, Mode, SectionKind, Terminal, MAGIC,
    SPEC_PARTS,
};
use shared_types::pwa::Child;

/// Arguments of `inspect`.
#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// Controller image file.
    pub image: std::path::PathBuf,
    /// Print the whole content as JSON.
    #[arg(long)]
    pub json: bool,
    /// The certificate `synth` wrote for this image (default: `certificate.json` beside the image, when
    /// there is one); with `--json`, its f64 δ, K and P, Goal steps, nominal states, f32 error bounds and
    /// PWA ball provenance are added under `"certificate"`. A certificate of another image is refused.
    #[arg(long, value_name = "FILE", requires = "json")]
    pub certificate: Option<std::path::PathBuf>,
}

/// Why an image could not be inspected.
#[derive(Debug, thiserror::Error, miette::Diagnostic)]
pub enum InspectError {
    /// The file could not be read.
    #[error("cannot read {path}")]
    Read {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The bytes are not a valid image.
    #[error("{path}: image rejected: {error}")]
    Rejected {
        /// File.
        path: String,
        /// What the decoder found.
        error: ImageError,
        /// Header summary, when the header itself could be read.
        #[help]
        header: Option<String>,
    },
    /// The certificate could not be read or is not JSON.
    #[error("cannot read the certificate {path}: {why}")]
    Certificate {
        /// File.
        path: String,
        /// Cause.
        why: String,
    },
    /// The certificate was not written for this image.
    #[error("{certificate} is not the certificate of {image}: {why}")]
    CertificateMismatch {
        certificate: String,
        image: String,
        why: String,
    },
}

/// Entry point of the subcommand.
pub fn run(a: &InspectArgs) -> miette::Result<()> {
    let path = a.image.display().to_string();
    let bytes = std::fs::read(&a.image).map_err(|source| InspectError::Read {
        path: path.clone(),
        source,
    })?;
    let mut out = render(&bytes, &path, a.json)?;
    if a.json {
        let items = checker_items(&bytes, &a.image, a.certificate.as_deref())?;
        // `render` printed a JSON object; the certificate's items join it.
        if let Ok(serde_json::Value::Object(mut o)) = serde_json::from_str(&out) {
            o.insert("certificate".into(), items);
            out = serde_json::to_string_pretty(&o)
                .unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"));
        }
    }
    // Write, not println!: a closed pipe (`inspect x | head`) must end quietly, not panic.
    let mut stdout = std::io::stdout().lock();
    match writeln!(stdout, "{out}") {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(miette::miette!("cannot write to stdout: {e}"))
        }
        _ => Ok(()),
    }
}

/// Decodes `bytes` and renders the content (JSON if `json`), or explains why the image is rejected.
pub fn render(bytes: &[u8], path: &str, json: bool) -> Result<String, InspectError> {
    let img = decode(bytes).map_err(|error| InspectError::Rejected {
        path: path.to_string(),
        error,
        header: Header::parse(bytes)
            .ok()
            .map(|h| header_line(&h, bytes.len())),
    })?;
    // decode succeeded, so the header parses.
    let h = Header::parse(bytes).map_err(|error| InspectError::Rejected {
        path: path.to_string(),
        error,
        header: None,
    })?;
    let mut report = Report::new(&img, &h, bytes.len());
    // decode succeeded, so the directory parses too.
    if let Ok(dir) = directory(bytes) {
        report.sections = (0..dir.len())
            .filter_map(|i| dir.entry(i))
            .map(|e| SectionJson {
                kind: SectionKind::from_u16(e.kind).map_or("unknown", |k| k.name()),
                tag: e.kind,
                offset: e.offset,
                len: e.len,
            })
            .collect();
    }
    if json {
        Ok(serde_json::to_string_pretty(&report)
            .unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}")))
    } else {
        Ok(summary(&report, path))
    }
}

fn header_line(h: &Header, size: usize) -> String {
    format!(
        "header: version {}, mode {}, n {}, m {}, locations {}, trajectories {}, partitions {}, period {} s, \
         sections {}, payload {} bytes, CRC {:#010x}; file {} bytes",
        h.version,
        h.mode,
        h.dims.n,
        h.dims.m,
        h.dims.n_locations,
        h.dims.n_trajectories,
        h.dims.n_partitions,
        h.period,
        h.n_sections,
        h.payload_len,
        h.crc,
        size
    )
}

#[derive(Serialize)]
struct HeaderJson {
    magic: String,
    version: u16,
    mode: &'static str,
    mode_value: u8,
    n: usize,
    m: usize,
    locations: usize,
    trajectories: usize,
    partitions: usize,
    period: f32,
    sections: u16,
    payload_len: u32,
    crc: String,
    size: usize,
}

/// One entry of the section directory.
#[derive(Serialize)]
struct SectionJson {
    kind: &'static str,
    tag: u16,
    offset: u32,
    len: u32,
}

/// One segment of the feedforward table.
#[derive(Serialize)]
struct SegmentJson {
    index: usize,
    trajectory: usize,
    location: usize,
    first_row: usize,
    steps: usize,
    /// How the segment ends (only for an image with the segment-exits section).
    #[serde(skip_serializing_if = "Option::is_none")]
    exit: Option<crate::emit::SegmentExit>,
}

#[derive(Serialize)]
struct LocationJson {
    index: usize,
    K: Vec<Vec<f32>>,
    P: Vec<Vec<f32>>,
}

#[derive(Serialize)]
struct TrajectoryJson {
    index: usize,
    centre: Vec<f32>,
    delta: f32,
    first_row: usize,
    steps: usize,
    location: Vec<usize>,
    v: Vec<Vec<f32>>,
}

#[derive(Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
enum FallbackJson {
    Hold,
    Zero,
    Linear {
        K: Vec<Vec<f32>>,
        x_ref: Vec<f32>,
        u_ref: Vec<f32>,
    },
    Constant {
        u: Vec<f32>,
    },
}

#[derive(Serialize)]
struct BoxJson {
    lo: Vec<f32>,
    hi: Vec<f32>,
}

#[derive(Serialize)]
#[serde(rename_all = "snake_case")]
enum ChildJson {
    Node(u16),
    Leaf(u16),
    Outside,
}

impl From<Child> for ChildJson {
    fn from(c: Child) -> Self {
        match c {
            Child::Node(i) => ChildJson::Node(i),
            Child::Leaf(l) => ChildJson::Leaf(l),
            Child::Outside => ChildJson::Outside,
        }
    }
}

impl std::fmt::Display for ChildJson {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ChildJson::Node(i) => write!(f, "node {i}"),
            ChildJson::Leaf(l) => write!(f, "leaf {l}"),
            ChildJson::Outside => f.write_str("OUTSIDE"),
        }
    }
}

#[derive(Serialize)]
struct LawJson {
    partition: usize,
    /// Full gain `K_j = K + θ_j`.
    K: Vec<Vec<f32>>,
    theta0: Vec<f32>,
    /// `θ_j = K_j − K_0` (f64 difference of the stored values), only for single-location images.
    #[serde(skip_serializing_if = "Option::is_none")]
    theta: Option<Vec<Vec<f64>>>,
}

#[derive(Serialize)]
struct NodeJson {
    node: usize,
    a: Vec<f32>,
    b: f32,
    left: ChildJson,
    right: ChildJson,
}

#[derive(Serialize)]
struct LeafJson {
    leaf: usize,
    partition: usize,
    balls: Vec<usize>,
}

#[derive(Serialize)]
struct BallJson {
    ball: usize,
    centre: Vec<f32>,
    /// Whitened centre `fl32(R̂ ĉ)` of the evaluator's ball test.
    centre_z: Vec<f32>,
    /// Squared threshold ŝ of the ball test (accept iff the computed squared whitened distance is ≤ ŝ).
    threshold: f32,
    location: usize,
    partition: usize,
}

#[derive(Serialize)]
struct PwaJson {
    tree_depth: usize,
    nodes: usize,
    leaves: usize,
    balls: usize,
    ball_refs: usize,
    max_leaf_balls: usize,
    /// Worst-case multiply-adds of one step for this image: depth·n + the largest over leaves of
    /// (whitenings·n(n+1)/2 + balls·n), whitenings = 1 + location changes along the leaf's list, + m·n.
    worst_case_muladds: usize,
    /// Per location, the upper-triangular factor R̂ of `P` used by the ball test.
    factors: Vec<Vec<Vec<f32>>>,
    laws: Vec<LawJson>,
    tree: Vec<NodeJson>,
    leaf_table: Vec<LeafJson>,
    ball_table: Vec<BallJson>,
}

/// The largest envelope-test work of one leaf, in multiply-adds: the whitening `z = R̂x` (n(n+1)/2, once
/// per run of balls of one location) and n per ball (`shared_types::pwa`, "Cost of one step").
fn leaf_muladds_max(img: &Image<'_>) -> usize {
    let n = img.n();
    (0..img.n_leaves())
        .map(|l| {
            let balls: Vec<usize> = (0..img.leaf_refs(l).1)
                .filter_map(|k| img.leaf_ball(l, k))
                .collect();
            let whitenings = 1 + balls
                .windows(2)
                .filter(|w| img.ball_location(w[0]) != img.ball_location(w[1]))
                .count();
            whitenings * n * (n + 1) / 2 + balls.len() * n
        })
        .max()
        .unwrap_or(0)
}

impl PwaJson {
    fn new(img: &Image<'_>) -> PwaJson {
        let (n, m) = (img.n(), img.m());
        let max_leaf_balls = (0..img.n_leaves())
            .map(|l| img.leaf_refs(l).1)
            .max()
            .unwrap_or(0);
        PwaJson {
            tree_depth: img.tree_depth(),
            nodes: img.n_nodes(),
            leaves: img.n_leaves(),
            balls: img.n_balls(),
            ball_refs: img.n_ball_refs(),
            max_leaf_balls,
            worst_case_muladds: img.tree_depth() * n + leaf_muladds_max(img) + m * n,
            factors: (0..img.n_locations())
                .map(|l| matrix(n, n, |r, c| img.factor(l, r, c)))
                .collect(),
            laws: (0..img.n_partitions())
                .map(|j| LawJson {
                    partition: j,
                    K: matrix(m, n, |r, c| img.law_gain(j, r, c)),
                    theta0: (0..m).map(|r| img.law_offset(j, r)).collect(),
                    theta: (img.n_locations() == 1).then(|| {
                        (0..m)
                            .map(|r| {
                                (0..n)
                                    .map(|c| img.law_gain(j, r, c) as f64 - img.K(0, r, c) as f64)
                                    .collect()
                            })
                            .collect()
                    }),
                })
                .collect(),
            tree: (0..img.n_nodes())
                .map(|i| {
                    let (l, r) = img
                        .node_children(i)
                        .unwrap_or((Child::Outside, Child::Outside));
                    NodeJson {
                        node: i,
                        a: (0..n).map(|k| img.node_normal(i, k)).collect(),
                        b: img.node_offset(i),
                        left: l.into(),
                        right: r.into(),
                    }
                })
                .collect(),
            leaf_table: (0..img.n_leaves())
                .map(|l| LeafJson {
                    leaf: l,
                    partition: img.leaf_partition(l),
                    balls: (0..img.leaf_refs(l).1)
                        .filter_map(|k| img.leaf_ball(l, k))
                        .collect(),
                })
                .collect(),
            ball_table: (0..img.n_balls())
                .map(|b| BallJson {
                    ball: b,
                    centre: (0..n).map(|i| img.ball_centre(b, i)).collect(),
                    centre_z: (0..n).map(|i| img.ball_centre_z(b, i)).collect(),
                    threshold: img.ball_threshold(b),
                    location: img.ball_location(b),
                    partition: img.ball_partition(b),
                })
                .collect(),
        }
    }
}

/// One model program.
#[derive(Serialize)]
struct ProgramJson {
    bytes: usize,
    inputs: usize,
    outputs: usize,
    consts: usize,
    code_len: usize,
    max_stack: usize,
}

impl ProgramJson {
    fn new(bytes: &[u8], p: &shared_types::program::Program<'_>) -> Self {
        ProgramJson {
            bytes: bytes.len(),
            inputs: p.n_inputs(),
            outputs: p.n_outputs(),
            consts: p.n_consts(),
            code_len: p.code_len(),
            max_stack: p.max_stack(),
        }
    }
}

/// The model maps section.
#[derive(Serialize)]
struct MapsJson {
    n_plant: usize,
    m_plant: usize,
    coords: ProgramJson,
    input_map: ProgramJson,
}

#[derive(Serialize)]
struct Report {
    header: HeaderJson,
    /// The section directory, in stored order.
    sections: Vec<SectionJson>,
    /// Feedforward segments (empty for a PWA image).
    segments: Vec<SegmentJson>,
    total_steps: usize,
    /// Feedforward only.
    #[serde(skip_serializing_if = "Option::is_none")]
    terminal: Option<&'static str>,
    fallback: FallbackJson,
    input_box: Option<BoxJson>,
    locations: Vec<LocationJson>,
    trajectories: Vec<TrajectoryJson>,
    /// PWA feedback only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pwa: Option<PwaJson>,
    /// The spec fingerprint: per part of the spec its hash in hex (`null`: the image stores none).
    spec_fingerprint: Option<Vec<FingerprintPartJson>>,
    /// Feedback-linearizable plants only.
    #[serde(skip_serializing_if = "Option::is_none")]
    model_maps: Option<MapsJson>,
    /// The terminal law (section 11; `null`: the image has none).
    terminal_law: Option<TerminalLawJson>,
    /// What the image does after Goal, in one line ([`crate::report::after_goal_line`]).
    after_goal: String,
    /// The task's monitor (section 14; `null`: the image has none).
    monitor: Option<MonitorJson>,
}

/// The monitor's capacities: what a firmware sizes its arena by.
#[derive(Serialize)]
struct MonitorJson {
    atoms: usize,
    nodes: usize,
    /// The horizon N: samples 0..=N are monitored.
    horizon: usize,
    /// The evaluator's arena in 32-bit words, and its RAM in bytes (arena and state).
    arena_words: usize,
    ram_bytes: usize,
}

/// The terminal law as stored (f32 values): its equilibrium, law u = K_t x + v_t and the ellipsoid
/// (x − x_e)ᵀP_t(x − x_e) ≤ radius² the evaluator hands over on.
#[derive(Serialize)]
struct TerminalLawJson {
    x_e: Vec<f32>,
    K: Vec<Vec<f32>>,
    v: Vec<f32>,
    P: Vec<Vec<f32>>,
    radius: f32,
}

#[derive(Serialize)]
struct FingerprintPartJson {
    part: &'static str,
    hash: String,
}

fn matrix(rows: usize, cols: usize, at: impl Fn(usize, usize) -> f32) -> Vec<Vec<f32>> {
    (0..rows)
        .map(|r| (0..cols).map(|c| at(r, c)).collect())
        .collect()
}

impl Report {
    fn new(img: &Image<'_>, h: &Header, size: usize) -> Report {
        let (n, m) = (img.n(), img.m());
        // The fallback and the box act on the plant's input (m itself without model maps).
        let mp = img.plant_m();
        Report {
            header: HeaderJson {
                magic: String::from_utf8_lossy(&MAGIC).into_owned(),
                version: h.version,
                mode: match img.mode() {
                    Mode::Feedforward => "feedforward",
                    Mode::PwaFeedback => "pwa_feedback",
                    _ => "unknown",
                },
                mode_value: img.mode() as u8,
                n,
                m,
                locations: img.n_locations(),
                trajectories: img.n_trajectories(),
                partitions: img.dims().n_partitions,
                period: img.period(),
                sections: h.n_sections,
                payload_len: h.payload_len,
                crc: format!("{:#010x}", h.crc),
                size,
            },
            sections: Vec::new(),
            spec_fingerprint: img
                .fingerprint()
                .and_then(crate::spec::SpecFingerprint::from_bytes)
                .map(|f| {
                    SPEC_PARTS
                        .iter()
                        .enumerate()
                        .map(|(i, &part)| FingerprintPartJson {
                            part,
                            hash: f.hex(i),
                        })
                        .collect()
                }),
            segments: (0..img.n_trajectories())
                .flat_map(|t| {
                    let (s0, count) = img.trajectory_segments(t);
                    (s0..s0 + count).map(move |s| (t, s))
                })
                .filter_map(|(t, s)| {
                    img.segment(s).map(|g| SegmentJson {
                        index: s,
                        trajectory: t,
                        location: g.location,
                        first_row: g.first_row,
                        steps: g.len,
                        exit: img
                            .has_exits()
                            .then(|| crate::emit::SegmentExit::of(img.exit(s))),
                    })
                })
                .collect(),
            total_steps: img.total_steps(),
            after_goal: crate::report::after_goal_line(img),
            terminal: (img.mode() == Mode::Feedforward).then_some(match img.terminal() {
                Terminal::HoldLast => "hold_last",
                Terminal::Fallback => "fallback",
            }),
            fallback: match img.fallback() {
                Fallback::Hold => FallbackJson::Hold,
                Fallback::Zero => FallbackJson::Zero,
                Fallback::Constant { .. } => FallbackJson::Constant {
                    u: (0..mp).map(|j| img.fallback_input(j)).collect(),
                },
                Fallback::Linear { .. } => FallbackJson::Linear {
                    K: matrix(m, n, |r, c| img.fallback_K(r, c)),
                    x_ref: (0..n).map(|i| img.fallback_x_ref(i)).collect(),
                    u_ref: (0..m).map(|j| img.fallback_u_ref(j)).collect(),
                },
            },
            input_box: img.has_input_box().then(|| {
                let b: Vec<(f32, f32)> = (0..mp).filter_map(|j| img.input_bounds(j)).collect();
                BoxJson {
                    lo: b.iter().map(|p| p.0).collect(),
                    hi: b.iter().map(|p| p.1).collect(),
                }
            }),
            locations: (0..img.n_locations())
                .map(|l| LocationJson {
                    index: l,
                    K: matrix(m, n, |r, c| img.K(l, r, c)),
                    P: matrix(n, n, |r, c| img.P(l, r, c)),
                })
                .collect(),
            trajectories: (0..img.n_trajectories())
                .map(|t| {
                    let (first_row, steps) = img.trajectory_rows(t);
                    TrajectoryJson {
                        index: t,
                        centre: (0..n).map(|i| img.centre(t, i)).collect(),
                        delta: img.delta(t),
                        first_row,
                        steps,
                        location: (0..steps).map(|s| img.location(t, s)).collect(),
                        v: matrix(steps, m, |s, j| img.v(t, s, j)),
                    }
                })
                .collect(),
            pwa: (img.mode() == Mode::PwaFeedback).then(|| PwaJson::new(img)),
            terminal_law: img.terminal_law().map(|t| {
                let f = |b: &[u8]| -> Vec<f32> {
                    b.chunks_exact(4)
                        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                        .collect()
                };
                let (K, P) = (f(t.K), f(t.P));
                TerminalLawJson {
                    x_e: f(t.x_e),
                    K: matrix(m, n, |r, c| K[r * n + c]),
                    v: f(t.v),
                    P: matrix(n, n, |r, c| P[r * n + c]),
                    radius: t.radius,
                }
            }),
            monitor: img.monitor().map(|p| MonitorJson {
                atoms: p.atoms(),
                nodes: p.nodes(),
                horizon: p.horizon(),
                arena_words: p.words(),
                ram_bytes: p.ram_bytes(),
            }),
            model_maps: img.model_maps().map(|mm| MapsJson {
                n_plant: mm.n_plant(),
                m_plant: mm.m_plant(),
                coords: ProgramJson::new(mm.coords_bytes(), &mm.coords()),
                input_map: ProgramJson::new(mm.input_map_bytes(), &mm.input_map()),
            }),
        }
    }
}

fn vec_str(v: &[f32]) -> String {
    let parts: Vec<String> = v.iter().map(|x| x.to_string()).collect();
    format!("[{}]", parts.join(", "))
}

/// Rows of the v table printed per trajectory in the summary (the JSON has all of them).
const SUMMARY_ROWS: usize = 6;
/// Laws, tree nodes, leaves and balls printed in the summary of a PWA image (the JSON has all of them).
const SUMMARY_ITEMS: usize = 8;

fn summary(r: &Report, path: &str) -> String {
    let h = &r.header;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{path}: valid controller image, {} bytes (header 32 + directory and sections {}), format {} v{}, CRC {} ok",
        h.size, h.payload_len, h.magic, h.version, h.crc
    );
    let _ = writeln!(
        s,
        "mode: {} ({}), sample period {} s",
        h.mode, h.mode_value, h.period
    );
    let _ = writeln!(s, "sections ({}):", r.sections.len());
    for e in &r.sections {
        let _ = writeln!(
            s,
            "  {:<12} (kind {}) bytes {}..{} ({} bytes)",
            e.kind,
            e.tag,
            e.offset,
            e.offset as u64 + e.len as u64,
            e.len
        );
    }
    if let Some(p) = &r.pwa {
        let _ = writeln!(
            s,
            "n = {}, m = {}, locations = {}, partitions = {}",
            h.n, h.m, h.locations, h.partitions
        );
        let _ = writeln!(
            s,
            "tree: {} nodes, depth {} (worst case), {} leaves; {} certified balls ({} references, at most {} per leaf)",
            p.nodes, p.tree_depth, p.leaves, p.balls, p.ball_refs, p.max_leaf_balls
        );
        let _ = writeln!(
            s,
            "worst case per step: {} hyperplane tests, {} ball tests, {} multiply-adds",
            p.tree_depth, p.max_leaf_balls, p.worst_case_muladds
        );
    } else {
        let _ = writeln!(
            s,
            "n = {}, m = {}, locations = {}, trajectories = {}, table rows = {}, partitions = {}",
            h.n, h.m, h.locations, h.trajectories, r.total_steps, h.partitions
        );
    }
    match &r.spec_fingerprint {
        Some(parts) => {
            let _ = writeln!(s, "spec fingerprint (SHA-256, first 8 bytes per part):");
            for p in parts {
                let _ = writeln!(s, "  {:<22} {}", p.part, p.hash);
            }
        }
        None => {
            let _ = writeln!(s, "spec fingerprint: none stored");
        }
    }
    if let Some(mm) = &r.model_maps {
        let _ = writeln!(
            s,
            "model maps: the law works on xi = coords(x) (n = {}) and gives w (m = {}); the plant has \
             n_plant = {}, m_plant = {}, u = input_map(x, w)",
            h.n, h.m, mm.n_plant, mm.m_plant
        );
        for (name, p) in [("coords", &mm.coords), ("input_map", &mm.input_map)] {
            let _ = writeln!(
                s,
                "  {name}: {} bytes, {} inputs, {} outputs, {} constants, {} bytes of code, stack depth {}",
                p.bytes, p.inputs, p.outputs, p.consts, p.code_len, p.max_stack
            );
        }
    }
    if let Some(t) = &r.terminal_law {
        let _ = writeln!(
            s,
            "terminal law (section 11): hands over where (x − x_e)ᵀP_t(x − x_e) ≤ {}², then u = K_t x + v_t\n  x_e = {:?}\n  K_t = {:?}\n  v_t = {:?}\n  P_t = {:?}",
            t.radius, t.x_e, t.K, t.v, t.P
        );
    }
    if let Some(t) = r.terminal {
        let _ = writeln!(
            s,
            "terminal: {}",
            match t {
                "hold_last" => "hold the last row (u = K x + v_last)",
                _ => "apply the fallback",
            }
        );
    }
    let _ = writeln!(s, "{}", r.after_goal);
    if let Some(m) = &r.monitor {
        let _ = writeln!(
            s,
            "monitor: {} atoms, {} nodes, samples 0..={}; arena {} words, {} bytes of RAM",
            m.atoms, m.nodes, m.horizon, m.arena_words, m.ram_bytes
        );
    }
    match &r.fallback {
        FallbackJson::Hold => {
            let _ = writeln!(s, "fallback: hold the last applied input");
        }
        FallbackJson::Zero => {
            let _ = writeln!(s, "fallback: zero input");
        }
        FallbackJson::Constant { u } => {
            let _ = writeln!(s, "fallback: the constant input u = {}", vec_str(u));
        }
        FallbackJson::Linear { K, x_ref, u_ref } => {
            let _ = writeln!(
                s,
                "fallback: u = K_fb (x - x_ref) + u_ref{}",
                if r.input_box.is_some() {
                    ", saturated to the input box"
                } else {
                    ""
                }
            );
            for (i, row) in K.iter().enumerate() {
                let _ = writeln!(s, "  K_fb[{i}] = {}", vec_str(row));
            }
            let _ = writeln!(s, "  x_ref = {}", vec_str(x_ref));
            let _ = writeln!(s, "  u_ref = {}", vec_str(u_ref));
        }
    }
    match &r.input_box {
        Some(b) => {
            let _ = writeln!(
                s,
                "input box: lo = {}, hi = {}",
                vec_str(&b.lo),
                vec_str(&b.hi)
            );
        }
        None => {
            let _ = writeln!(s, "input box: none");
        }
    }
    for l in &r.locations {
        let _ = writeln!(s, "location {}:", l.index);
        for (i, row) in l.K.iter().enumerate() {
            let _ = writeln!(s, "  K[{i}] = {}", vec_str(row));
        }
        for (i, row) in l.P.iter().enumerate() {
            let _ = writeln!(s, "  P[{i}] = {}", vec_str(row));
        }
    }
    if let Some(p) = &r.pwa {
        pwa_summary(&mut s, p);
    }
    for t in &r.trajectories {
        let _ = writeln!(
            s,
            "trajectory {}: ball centre {}, delta {}, {} steps (rows {}..{})",
            t.index,
            vec_str(&t.centre),
            t.delta,
            t.steps,
            t.first_row,
            t.first_row + t.steps
        );
        for g in r.segments.iter().filter(|g| g.trajectory == t.index) {
            let _ = writeln!(
                s,
                "  segment {}: location {}, rows {}..{}",
                g.index,
                g.location,
                g.first_row,
                g.first_row + g.steps
            );
        }
        for (k, row) in t.v.iter().enumerate().take(SUMMARY_ROWS) {
            let _ = writeln!(s, "  v({k}) = {}  location {}", vec_str(row), t.location[k]);
        }
        if t.steps > SUMMARY_ROWS {
            let last = t.steps - 1;
            let _ = writeln!(
                s,
                "  ... {} more rows; v({last}) = {}  location {} (all rows with --json)",
                t.steps - SUMMARY_ROWS,
                vec_str(&t.v[last]),
                t.location[last]
            );
        }
    }
    s.truncate(s.trim_end().len());
    s
}

/// The PWA part of the summary: laws, tree, leaves and balls (the first [`SUMMARY_ITEMS`] of each).
fn pwa_summary(s: &mut String, p: &PwaJson) {
    let more = |s: &mut String, total: usize, what: &str| {
        if total > SUMMARY_ITEMS {
            let _ = writeln!(
                s,
                "  ... {} more {what} (all with --json)",
                total - SUMMARY_ITEMS
            );
        }
    };
    for law in p.laws.iter().take(SUMMARY_ITEMS) {
        let _ = writeln!(
            s,
            "partition {}: u = K_j x + theta0_j, theta0_j = {}",
            law.partition,
            vec_str(&law.theta0)
        );
        for (i, row) in law.K.iter().enumerate() {
            let _ = writeln!(s, "  K_j[{i}] = {}", vec_str(row));
        }
        if let Some(theta) = &law.theta {
            for (i, row) in theta.iter().enumerate() {
                let row: Vec<String> = row.iter().map(|x| x.to_string()).collect();
                let _ = writeln!(s, "  theta_j[{i}] = [{}]", row.join(", "));
            }
        }
    }
    more(s, p.laws.len(), "partitions");
    if p.tree.is_empty() {
        let _ = writeln!(s, "tree: leaf 0 alone (no hyperplanes)");
    } else {
        let _ = writeln!(s, "tree (a^T x <= b goes left):");
    }
    for n in p.tree.iter().take(SUMMARY_ITEMS) {
        let _ = writeln!(
            s,
            "  node {}: a = {}, b = {} -> left {}, right {}",
            n.node,
            vec_str(&n.a),
            n.b,
            n.left,
            n.right
        );
    }
    more(s, p.tree.len(), "nodes");
    for l in p.leaf_table.iter().take(SUMMARY_ITEMS) {
        let balls: Vec<String> = l.balls.iter().map(|b| b.to_string()).collect();
        let _ = writeln!(
            s,
            "leaf {}: partition {}, balls [{}]",
            l.leaf,
            l.partition,
            balls.join(", ")
        );
    }
    more(s, p.leaf_table.len(), "leaves");
    for b in p.ball_table.iter().take(SUMMARY_ITEMS) {
        let _ = writeln!(
            s,
            "ball {}: centre {}, threshold {}, location {}, partition {}",
            b.ball,
            vec_str(&b.centre),
            b.threshold,
            b.location,
            b.partition
        );
    }
    more(s, p.ball_table.len(), "balls");
}

/// The items an independent checker needs from the certificate (module doc, "For independent
/// checkers"), or which are missing and why. `explicit`: the `--certificate` flag; without it
/// `certificate.json` beside the image is read when it exists and names this image's file.
pub fn checker_items(
    bytes: &[u8],
    image: &std::path::Path,
    explicit: Option<&std::path::Path>,
) -> Result<serde_json::Value, InspectError> {
    let path = match explicit {
        Some(p) => p.to_path_buf(),
        None => image
            .parent()
            .unwrap_or(std::path::Path::new("."))
            .join("certificate.json"),
    };
    if explicit.is_none() && !path.is_file() {
        return Ok(absent(format!(
            "no --certificate was given and there is no {} beside the image",
            path.display()
        )));
    }
    let failed = |why: String| InspectError::Certificate {
        path: path.display().to_string(),
        why,
    };
    let text = std::fs::read_to_string(&path).map_err(|e| failed(e.to_string()))?;
    let cert: serde_json::Value = serde_json::from_str(&text).map_err(|e| failed(e.to_string()))?;
    let mismatch = |why: String| InspectError::CertificateMismatch {
        certificate: path.display().to_string(),
        image: image.display().to_string(),
        why,
    };
    let sha = super::sha256_hex(bytes);
    let id = &cert["image"];
    let named = id["file"].as_str();
    let this_file = image.file_name().map(|f| f.to_string_lossy().into_owned());
    match id["sha256"].as_str() {
        Some(h) if h == sha => Ok(present(&cert, &path, &sha, bytes)),
        // The certificate beside the image is another file's (a PWA run's feedforward.img sits next to
        // the certificate of controller.img): nothing of this image's, not an error.
        _ if explicit.is_none() && named.is_some_and(|f| Some(f) != this_file.as_deref()) => {
            Ok(absent(format!(
                "{} beside the image is the certificate of {}, not of this file",
                path.display(),
                named.unwrap_or("?")
            )))
        }
        // An older certificate beside the image (written before certificates named their image): it
        // cannot be told to be this image's, so none of it is shown.
        None if explicit.is_none() => Ok(absent(format!(
            "{} beside the image records no image identity (written before certificates named their \
             image): it cannot be told to belong to this image",
            path.display()
        ))),
        Some(h) => Err(mismatch(format!(
            "it was written for an image with SHA-256 {h}{}, but this image's is {sha} ({} bytes)",
            id["bytes"]
                .as_u64()
                .map(|b| format!(" ({b} bytes)"))
                .unwrap_or_default(),
            bytes.len()
        ))),
        None => Err(mismatch(
            "it records no image identity (\"image\": its SHA-256), so it cannot be told to belong to \
             this image; synthesise again to get a certificate that does"
                .into(),
        )),
    }
}

/// What a checker needs that only the certificate holds.
const CHECKER_ITEMS: [&str; 6] = [
    "delta (the certified f64 radius per trajectory)",
    "K and P (f64)",
    "goal_step (per trajectory)",
    "nominal (the nominal states per trajectory)",
    "f32_error_bound (per trajectory)",
    "balls (a PWA ball's provenance and successor)",
];

fn absent(why: String) -> serde_json::Value {
    serde_json::json!({ "status": "absent", "why": why, "missing": CHECKER_ITEMS })
}

/// The checker's items of a certificate that belongs to the image, in one shape for every task: per
/// trajectory (per run for a hybrid image) its certified δ, stored radius, Goal step, f32 rounding
/// bound and nominal states.
fn present(
    cert: &serde_json::Value,
    path: &std::path::Path,
    sha: &str,
    bytes: &[u8],
) -> serde_json::Value {
    use serde_json::{json, Value};
    let task = cert["task"].as_str().unwrap_or("reach_avoid");
    let stored: Vec<f32> = decode(bytes)
        .map(|img| {
            if img.mode() == Mode::Feedforward {
                (0..img.n_trajectories()).map(|t| img.delta(t)).collect()
            } else {
                Vec::new()
            }
        })
        .unwrap_or_default();
    let matches = |i: usize, c: &Value| -> Value {
        match (stored.get(i), c["delta_stored"].as_f64()) {
            (Some(&s), Some(d)) => json!(s == d as f32),
            _ => Value::Null,
        }
    };
    let mut out = json!({
        "status": "present",
        "file": path.display().to_string(),
        "task": task,
        "image_sha256": sha,
    });
    let trajectories: Vec<Value> =
        if task == "hybrid" {
            out["locations"] = cert["locations"].clone();
            cert["runs"]
            .as_array()
            .map(Vec::as_slice)
            .unwrap_or_default()
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let c = &r["certificate"];
                let segs = c["segments"].as_array().map(Vec::as_slice).unwrap_or_default();
                let eps = segs
                    .iter()
                    .filter_map(|s| s["base"]["eps_f32"].as_f64())
                    .fold(None, |m: Option<f64>, e| Some(m.map_or(e, |m| m.max(e))));
                json!({
                    "index": i,
                    "delta": segs.first().map(|s| s["delta"].clone()),
                    "delta_stored": c["delta_stored"],
                    "stored_radius_matches_image": matches(i, c),
                    // Σ κ_f + κ*: the last sample a run of this ball may take to reach Goal.
                    "goal_step": segs.iter().map(|s| s["samples"].as_u64()).sum::<Option<u64>>(),
                    "f32_error_bound": eps,
                    "nominal_segments": r["nominal_segments"],
                })
            })
            .collect()
        } else {
            out["K"] = cert["K"].clone();
            out["P"] = cert["P"].clone();
            cert["trajectories"]
                .as_array()
                .map(Vec::as_slice)
                .unwrap_or_default()
                .iter()
                .enumerate()
                .map(|(i, t)| {
                    let c = &t["certificate"];
                    json!({
                        "index": i,
                        "delta": c["delta"],
                        "delta_stored": c["delta_stored"],
                        "stored_radius_matches_image": matches(i, c),
                        // An MTL task has no Goal step: its formula is judged over the whole run.
                        "goal_step": if task == "mtl" { Value::Null } else { c["k_star"].clone() },
                        "f32_error_bound": c["eps_f32"],
                        "nominal": t["nominal"],
                    })
                })
                .collect()
        };
    out["trajectories"] = Value::Array(trajectories);
    if task == "pwa" {
        out["balls"] = cert["balls"].clone();
    }
    // Items an older certificate does not hold (written before they were recorded).
    let mut missing: Vec<&str> = Vec::new();
    let first = &out["trajectories"][0];
    if first["nominal"].is_null() && first["nominal_segments"].is_null() {
        missing.push(CHECKER_ITEMS[3]);
    }
    if task == "pwa" && out["balls"].is_null() {
        missing.push(CHECKER_ITEMS[5]);
    }
    out["missing"] = json!(missing);
    out
}
