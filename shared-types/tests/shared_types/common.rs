//! Test helpers: an owned, std-side description of image content (feedforward and PWA feedback), its
//! conversion to bytes, and seeded generators of random valid contents.
#![allow(dead_code, non_snake_case)]

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use shared_types::capacity::MAX_IMAGE_LEN;
use shared_types::image::{
    encode, write_image, Dims, Fallback, FallbackSection, Image, ImageError, InputBox,
    LocationsSection, Mode, Payload, PostcardSection, PwaPayload, RawSection, SectionKind,
    SectionWrite, Terminal,
};

#[derive(Clone, Debug, PartialEq)]
pub enum FallbackC {
    Hold,
    Zero,
    Linear {
        K: Vec<f32>,
        x_ref: Vec<f32>,
        u_ref: Vec<f32>,
    },
    /// A constant input (m values).
    Constant(Vec<f32>),
}

/// Image content with owned f32 arrays (row-major), as a test would write it down.
#[derive(Clone, Debug, PartialEq)]
pub struct Content {
    pub n: usize,
    pub m: usize,
    pub nl: usize,
    pub period: f32,
    pub K: Vec<f32>,
    pub P: Vec<f32>,
    pub traj_len: Vec<usize>,
    pub centre: Vec<f32>,
    pub delta: Vec<f32>,
    pub v: Vec<f32>,
    pub location: Vec<u8>,
    pub fallback: FallbackC,
    pub input_box: Option<(Vec<f32>, Vec<f32>)>,
    pub terminal: Terminal,
}

pub fn le(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Owned byte strings for every payload field.
pub struct Owned {
    pub K: Vec<u8>,
    pub P: Vec<u8>,
    pub seg_end: Vec<u8>,
    pub centre: Vec<u8>,
    pub delta: Vec<u8>,
    pub segment: Vec<u8>,
    pub v: Vec<u8>,
    pub fb: Option<(Vec<u8>, Vec<u8>, Vec<u8>)>,
    pub fb_kind: u8,
    pub bx: Option<(Vec<u8>, Vec<u8>)>,
    pub terminal: Terminal,
}

impl Owned {
    pub fn payload(&self) -> Payload<'_> {
        Payload {
            K: &self.K,
            P: &self.P,
            seg_end: &self.seg_end,
            centre: &self.centre,
            delta: &self.delta,
            segment: &self.segment,
            v: &self.v,
            fallback: match (&self.fb, self.fb_kind) {
                (Some((_, _, u)), 3) => Fallback::Constant { u },
                (Some((K, x, u)), _) => Fallback::Linear {
                    K,
                    x_ref: x,
                    u_ref: u,
                },
                (None, 0) => Fallback::Hold,
                _ => Fallback::Zero,
            },
            input_box: self.bx.as_ref().map(|(lo, hi)| InputBox { lo, hi }),
            terminal: self.terminal,
            exits: &[],
        }
    }
}

impl Content {
    pub fn dims(&self) -> Dims {
        Dims {
            n: self.n,
            m: self.m,
            n_locations: self.nl,
            n_trajectories: self.traj_len.len(),
            n_partitions: 0,
        }
    }

    /// The segments of the content: each trajectory's rows split into maximal runs of one location, as
    /// `(first_row, len, location)`, with each trajectory's exclusive segment end. Rows past the end of
    /// `location` count as location 0 (so that a short `location` still gives a table).
    pub fn segments(&self) -> (Vec<u16>, Vec<(u32, u32, u8)>) {
        let mut seg_end = Vec::new();
        let mut segs: Vec<(u32, u32, u8)> = Vec::new();
        let mut row = 0usize;
        for &len in &self.traj_len {
            let first_seg = segs.len();
            for r in row..row + len {
                let l = self.location.get(r).copied().unwrap_or(0);
                let continues = segs.len() > first_seg;
                match segs.last_mut() {
                    Some(s) if continues && s.2 == l => s.1 += 1,
                    _ => segs.push((r as u32, 1, l)),
                }
            }
            row += len;
            seg_end.push(segs.len() as u16);
        }
        (seg_end, segs)
    }

    pub fn owned(&self) -> Owned {
        let (seg_end, segs) = self.segments();
        Owned {
            K: le(&self.K),
            P: le(&self.P),
            seg_end: seg_end.iter().flat_map(|e| e.to_le_bytes()).collect(),
            centre: le(&self.centre),
            delta: le(&self.delta),
            segment: segs
                .iter()
                .flat_map(|&(f, n, l)| {
                    let mut r = f.to_le_bytes().to_vec();
                    r.extend_from_slice(&n.to_le_bytes());
                    r.push(l);
                    r
                })
                .collect(),
            v: le(&self.v),
            fb: match &self.fallback {
                FallbackC::Linear { K, x_ref, u_ref } => Some((le(K), le(x_ref), le(u_ref))),
                FallbackC::Constant(u) => Some((vec![], vec![], le(u))),
                _ => None,
            },
            fb_kind: match self.fallback {
                FallbackC::Hold => 0,
                FallbackC::Zero => 1,
                FallbackC::Linear { .. } => 2,
                FallbackC::Constant(_) => 3,
            },
            bx: self.input_box.as_ref().map(|(lo, hi)| (le(lo), le(hi))),
            terminal: self.terminal,
        }
    }

    /// Validates and encodes.
    pub fn to_bytes(&self) -> Result<Vec<u8>, ImageError> {
        let owned = self.owned();
        let img = Image::new(Mode::Feedforward, self.dims(), self.period, owned.payload())?;
        let mut buf = vec![0u8; MAX_IMAGE_LEN];
        let len = encode(&img, &mut buf)?;
        buf.truncate(len);
        Ok(buf)
    }

    /// Reads the content back out of a decoded image through its accessors.
    pub fn from_image(img: &Image<'_>) -> Content {
        let (n, m, nl, nt) = (img.n(), img.m(), img.n_locations(), img.n_trajectories());
        let mut c = Content {
            n,
            m,
            nl,
            period: img.period(),
            K: vec![],
            P: vec![],
            traj_len: (0..nt).map(|t| img.trajectory_len(t)).collect(),
            centre: vec![],
            delta: (0..nt).map(|t| img.delta(t)).collect(),
            v: vec![],
            location: vec![],
            fallback: match img.fallback() {
                Fallback::Hold => FallbackC::Hold,
                Fallback::Zero => FallbackC::Zero,
                Fallback::Constant { .. } => {
                    FallbackC::Constant((0..m).map(|j| img.fallback_input(j)).collect())
                }
                Fallback::Linear { .. } => FallbackC::Linear {
                    K: (0..m)
                        .flat_map(|r| (0..n).map(move |c| (r, c)))
                        .map(|(r, c)| img.fallback_K(r, c))
                        .collect(),
                    x_ref: (0..n).map(|i| img.fallback_x_ref(i)).collect(),
                    u_ref: (0..m).map(|j| img.fallback_u_ref(j)).collect(),
                },
            },
            input_box: if img.has_input_box() {
                let b: Vec<(f32, f32)> = (0..m).map(|j| img.input_bounds(j).unwrap()).collect();
                Some((
                    b.iter().map(|p| p.0).collect(),
                    b.iter().map(|p| p.1).collect(),
                ))
            } else {
                None
            },
            terminal: img.terminal(),
        };
        for l in 0..nl {
            for r in 0..m {
                for col in 0..n {
                    c.K.push(img.K(l, r, col));
                }
            }
            for r in 0..n {
                for col in 0..n {
                    c.P.push(img.P(l, r, col));
                }
            }
        }
        for t in 0..nt {
            for i in 0..n {
                c.centre.push(img.centre(t, i));
            }
            for s in 0..img.trajectory_len(t) {
                c.location.push(img.location(t, s) as u8);
                for j in 0..m {
                    c.v.push(img.v(t, s, j));
                }
            }
        }
        c
    }
}

/// A random symmetric positive definite n×n matrix (AᵀA + n·I, computed in f64, exactly symmetric in f32).
pub fn random_spd(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
    let a: Vec<f64> = (0..n * n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let mut p = vec![0.0f32; n * n];
    for i in 0..n {
        for j in i..n {
            let mut s: f64 = (0..n).map(|k| a[k * n + i] * a[k * n + j]).sum();
            if i == j {
                s += n as f64;
            }
            p[i * n + j] = s as f32;
            p[j * n + i] = s as f32;
        }
    }
    p
}

/// A random valid content with dimensions up to the given bounds.
pub fn random_content(
    rng: &mut ChaCha8Rng,
    max_n: usize,
    max_m: usize,
    max_traj: usize,
    max_len: usize,
) -> Content {
    let n = rng.random_range(1..=max_n);
    let m = rng.random_range(1..=max_m);
    let nl = rng.random_range(1..=3);
    let nt = rng.random_range(1..=max_traj);
    let traj_len: Vec<usize> = (0..nt).map(|_| rng.random_range(1..=max_len)).collect();
    let rows: usize = traj_len.iter().sum();
    let mut u =
        |k: usize, s: f32| -> Vec<f32> { (0..k).map(|_| rng.random_range(-s..s)).collect() };
    let K = u(nl * m * n, 3.0);
    let centre = u(nt * n, 5.0);
    let v = u(rows * m, 10.0);
    let fb_K = u(m * n, 2.0);
    let x_ref = u(n, 1.0);
    let u_ref = u(m, 1.0);
    let P: Vec<f32> = (0..nl).flat_map(|_| random_spd(rng, n)).collect();
    let delta = (0..nt).map(|_| rng.random_range(0.0..3.0)).collect();
    let location = (0..rows).map(|_| rng.random_range(0..nl as u8)).collect();
    let fallback = match rng.random_range(0..3) {
        0 => FallbackC::Hold,
        1 => FallbackC::Zero,
        _ => FallbackC::Linear {
            K: fb_K,
            x_ref,
            u_ref,
        },
    };
    let input_box = if rng.random_bool(0.5) {
        let lo: Vec<f32> = (0..m).map(|_| rng.random_range(-5.0..0.0)).collect();
        let hi: Vec<f32> = (0..m).map(|_| rng.random_range(0.0..5.0)).collect();
        Some((lo, hi))
    } else {
        None
    };
    Content {
        n,
        m,
        nl,
        period: rng.random_range(0.001..1.0),
        K,
        P,
        traj_len,
        centre,
        delta,
        v,
        location,
        fallback,
        input_box,
        terminal: if rng.random_bool(0.5) {
            Terminal::HoldLast
        } else {
            Terminal::Fallback
        },
    }
}

/// Sections of an image as `(kind, body)`, in directory order.
pub type Sections = Vec<(u16, Vec<u8>)>;

/// The directory entries of an image as `(kind, body)`, read naively from the header's section count and
/// the entries' offsets and lengths (the bytes must be laid out validly).
pub fn sections_of(bytes: &[u8]) -> Sections {
    let count = u16::from_le_bytes([bytes[18], bytes[19]]) as usize;
    (0..count)
        .map(|i| {
            let e = &bytes[32 + 12 * i..44 + 12 * i];
            let kind = u16::from_le_bytes([e[0], e[1]]);
            let off = u32::from_le_bytes(e[4..8].try_into().unwrap()) as usize;
            let len = u32::from_le_bytes(e[8..12].try_into().unwrap()) as usize;
            (kind, bytes[off..off + len].to_vec())
        })
        .collect()
}

/// An image with the header (mode, dimensions, period) of `like` and these sections, laid out validly by
/// `write_image` (directory, offsets, payload length and CRC), whatever the sections hold.
pub fn with_sections(like: &[u8], sections: &[(u16, Vec<u8>)]) -> Vec<u8> {
    let h = shared_types::image::Header::parse(like).unwrap();
    let raw: Vec<RawSection<'_>> = sections
        .iter()
        .map(|(kind, body)| RawSection { kind: *kind, body })
        .collect();
    let refs: Vec<&dyn SectionWrite> = raw.iter().map(|r| r as &dyn SectionWrite).collect();
    let mut buf = vec![0u8; like.len() + 4096 + sections.iter().map(|s| s.1.len()).sum::<usize>()];
    let len = write_image(&mut buf, h.mode, h.dims, h.period, &refs).unwrap();
    buf.truncate(len);
    buf
}

/// Patches the header's payload length and CRC to match the bytes.
pub fn fix_header(bytes: &mut [u8]) {
    if bytes.len() < 32 {
        return;
    }
    let plen = (bytes.len() - 32) as u32;
    bytes[24..28].copy_from_slice(&plen.to_le_bytes());
    let crc = shared_types::image::compute_crc(bytes).unwrap();
    bytes[28..32].copy_from_slice(&crc.to_le_bytes());
}

// ---- PWA-feedback content -------------------------------------------------------------------------------

use shared_types::capacity::{MAX_TREE_DEPTH, MAX_TREE_NODES};
use shared_types::pwa::{Child, PwaTables, LEAF_BASE, OUTSIDE};

/// PWA image content with owned arrays, as a test would write it down. Counts are the array lengths
/// (nodes = `node_b.len()`, leaves = `leaf_partition.len()`, balls = `ball_threshold.len()`) unless overridden.
/// The node fields and the ball test fields are kept apart here and interleaved into the image's records
/// by [`PwaContent::owned`] (values missing from a short field are left out, so the record table comes out
/// short).
#[derive(Clone, Debug, PartialEq)]
pub struct PwaContent {
    pub n: usize,
    pub m: usize,
    pub nl: usize,
    pub np: usize,
    pub period: f32,
    pub K: Vec<f32>,
    pub P: Vec<f32>,
    pub gain: Vec<f32>,
    pub offset: Vec<f32>,
    pub depth: u8,
    pub node_a: Vec<f32>,
    pub node_b: Vec<f32>,
    /// Two child codes per node (left, right).
    pub node_child: Vec<u16>,
    pub leaf_partition: Vec<u16>,
    pub leaf_balls: Vec<Vec<u16>>,
    /// Per location the upper-triangular factor of `P` (see [`PwaContent::whiten`]).
    pub R: Vec<f32>,
    pub ball_centre: Vec<f32>,
    /// Whitened centres `fl32(R̂ ĉ)` (see [`PwaContent::whiten`]).
    pub ball_centre_z: Vec<f32>,
    /// Squared thresholds ŝ of the ball test.
    pub ball_threshold: Vec<f32>,
    pub ball_location: Vec<u8>,
    pub ball_partition: Vec<u16>,
    pub fallback: FallbackC,
    pub input_box: Option<(Vec<f32>, Vec<f32>)>,
    /// Header trajectory count (0 for a valid PWA image).
    pub n_trajectories: usize,
    /// Overrides of the stored (nodes, leaves, balls) counts.
    pub counts: Option<(u16, u16, u16)>,
}

pub fn le16(v: &[u16]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Owned byte strings of every PWA payload field.
pub struct OwnedPwa {
    pub K: Vec<u8>,
    pub P: Vec<u8>,
    pub gain: Vec<u8>,
    pub offset: Vec<u8>,
    pub node: Vec<u8>,
    pub leaf_partition: Vec<u8>,
    pub leaf_end: Vec<u8>,
    pub ball_ref: Vec<u8>,
    pub R: Vec<u8>,
    pub ball_centre: Vec<u8>,
    pub ball_test: Vec<u8>,
    pub ball_location: Vec<u8>,
    pub ball_partition: Vec<u8>,
    pub fb: Option<(Vec<u8>, Vec<u8>, Vec<u8>)>,
    pub fb_kind: u8,
    pub bx: Option<(Vec<u8>, Vec<u8>)>,
    pub depth: u8,
    pub counts: (u16, u16, u16),
}

impl OwnedPwa {
    pub fn payload(&self) -> PwaPayload<'_> {
        PwaPayload {
            K: &self.K,
            P: &self.P,
            tables: PwaTables {
                depth: self.depth,
                n_nodes: self.counts.0,
                n_leaves: self.counts.1,
                n_balls: self.counts.2,
                gain: &self.gain,
                offset: &self.offset,
                node: &self.node,
                leaf_partition: &self.leaf_partition,
                leaf_end: &self.leaf_end,
                ball_ref: &self.ball_ref,
                R: &self.R,
                ball_centre: &self.ball_centre,
                ball_test: &self.ball_test,
                ball_location: &self.ball_location,
                ball_partition: &self.ball_partition,
            },
            fallback: match (&self.fb, self.fb_kind) {
                (Some((_, _, u)), 3) => Fallback::Constant { u },
                (Some((K, x, u)), _) => Fallback::Linear {
                    K,
                    x_ref: x,
                    u_ref: u,
                },
                (None, 0) => Fallback::Hold,
                _ => Fallback::Zero,
            },
            input_box: self.bx.as_ref().map(|(lo, hi)| InputBox { lo, hi }),
        }
    }
}

/// Worst-case number of tests from node 0 over a child-code array (children after parents assumed; back
/// edges are ignored). 0 for an empty tree.
pub fn tree_depth(node_child: &[u16]) -> u8 {
    let nn = node_child.len() / 2;
    if nn == 0 {
        return 0;
    }
    let mut d = vec![0usize; nn];
    d[0] = 1;
    for i in 0..nn {
        for side in 0..2 {
            if let Child::Node(c) = Child::from_code(node_child[2 * i + side]) {
                let c = c as usize;
                if c > i && c < nn && d[i] > 0 {
                    d[c] = d[c].max(d[i] + 1);
                }
            }
        }
    }
    d.into_iter().max().unwrap_or(0).min(255) as u8
}

/// The upper Cholesky factor of the f32 metric `P` (n × n), computed in f64 and rounded to f32, as the
/// host emits it; `None` if `P` is not positive definite in f64.
pub fn factor_of(P: &[f32], n: usize) -> Option<Vec<f32>> {
    let mut R = vec![0.0f64; n * n];
    for i in 0..n {
        let mut d = P[i * n + i] as f64;
        for k in 0..i {
            d -= R[k * n + i] * R[k * n + i];
        }
        if d.is_nan() || d <= 0.0 {
            return None;
        }
        R[i * n + i] = d.sqrt();
        for j in (i + 1)..n {
            let mut s = P[i * n + j] as f64;
            for k in 0..i {
                s -= R[k * n + i] * R[k * n + j];
            }
            R[i * n + j] = s / R[i * n + i];
        }
    }
    Some(R.iter().map(|&r| r as f32).collect())
}

/// `fl32(R̂ c)` for an upper-triangular n × n `R̂`, summed in f64.
pub fn whiten_centre(R: &[f32], c: &[f32]) -> Vec<f32> {
    let n = c.len();
    (0..n)
        .map(|i| {
            (i..n)
                .map(|j| R[i * n + j] as f64 * c[j] as f64)
                .sum::<f64>() as f32
        })
        .collect()
}

impl PwaContent {
    /// [`PwaContent::whiten`], by value.
    pub fn whitened(mut self) -> Self {
        self.whiten();
        self
    }

    /// Recomputes `R` from `P` (every location) and the whitened centres from the centres, as the host
    /// emitter does. Panics if a `P` is not positive definite (test content only).
    pub fn whiten(&mut self) {
        let n = self.n;
        self.R = (0..self.nl)
            .flat_map(|l| factor_of(&self.P[l * n * n..(l + 1) * n * n], n).expect("P is PD"))
            .collect();
        self.ball_centre_z = (0..self.ball_location.len())
            .flat_map(|b| {
                let l = self.ball_location[b] as usize;
                whiten_centre(
                    &self.R[l * n * n..(l + 1) * n * n],
                    &self.ball_centre[b * n..(b + 1) * n],
                )
            })
            .collect();
    }

    pub fn dims(&self) -> Dims {
        Dims {
            n: self.n,
            m: self.m,
            n_locations: self.nl,
            n_trajectories: self.n_trajectories,
            n_partitions: self.np,
        }
    }

    pub fn owned(&self) -> OwnedPwa {
        let mut ends = Vec::new();
        let mut refs = Vec::new();
        for balls in &self.leaf_balls {
            refs.extend_from_slice(balls);
            ends.push(refs.len() as u16);
        }
        OwnedPwa {
            K: le(&self.K),
            P: le(&self.P),
            gain: le(&self.gain),
            offset: le(&self.offset),
            node: self.node_records(),
            leaf_partition: le16(&self.leaf_partition),
            leaf_end: le16(&ends),
            ball_ref: le16(&refs),
            R: le(&self.R),
            ball_centre: le(&self.ball_centre),
            ball_test: self.ball_records(),
            ball_location: self.ball_location.clone(),
            ball_partition: le16(&self.ball_partition),
            fb: match &self.fallback {
                FallbackC::Linear { K, x_ref, u_ref } => Some((le(K), le(x_ref), le(u_ref))),
                FallbackC::Constant(u) => Some((vec![], vec![], le(u))),
                _ => None,
            },
            fb_kind: match self.fallback {
                FallbackC::Hold => 0,
                FallbackC::Zero => 1,
                FallbackC::Linear { .. } => 2,
                FallbackC::Constant(_) => 3,
            },
            bx: self.input_box.as_ref().map(|(lo, hi)| (le(lo), le(hi))),
            depth: self.depth,
            counts: self.counts.unwrap_or((
                self.node_b.len() as u16,
                self.leaf_partition.len() as u16,
                self.ball_threshold.len() as u16,
            )),
        }
    }

    /// The node record table: per node `a` (n f32), `b` (f32), left and right child (u16), for as many
    /// nodes as any node field covers; values a short field lacks are left out.
    pub fn node_records(&self) -> Vec<u8> {
        let n = self.n;
        let count = self
            .node_b
            .len()
            .max(self.node_a.len().div_ceil(n.max(1)))
            .max(self.node_child.len().div_ceil(2));
        let mut out = Vec::new();
        for i in 0..count {
            for k in 0..n {
                if let Some(v) = self.node_a.get(i * n + k) {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
            if let Some(v) = self.node_b.get(i) {
                out.extend_from_slice(&v.to_le_bytes());
            }
            for side in 0..2 {
                if let Some(c) = self.node_child.get(2 * i + side) {
                    out.extend_from_slice(&c.to_le_bytes());
                }
            }
        }
        out
    }

    /// The ball test record table: per ball the whitened centre (n f32) and the threshold (f32), for as
    /// many balls as either field covers; values a short field lacks are left out.
    pub fn ball_records(&self) -> Vec<u8> {
        let n = self.n;
        let count = self
            .ball_threshold
            .len()
            .max(self.ball_centre_z.len().div_ceil(n.max(1)));
        let mut out = Vec::new();
        for b in 0..count {
            for k in 0..n {
                if let Some(v) = self.ball_centre_z.get(b * n + k) {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
            if let Some(v) = self.ball_threshold.get(b) {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out
    }

    /// Validates (through `Image::new_pwa`) and encodes.
    pub fn to_bytes(&self) -> Result<Vec<u8>, ImageError> {
        let owned = self.owned();
        let img = Image::new_pwa(self.dims(), self.period, owned.payload())?;
        let mut buf = vec![0u8; MAX_IMAGE_LEN];
        let len = encode(&img, &mut buf)?;
        buf.truncate(len);
        Ok(buf)
    }

    /// Header, directory and sections written directly by `write_image`, without validation (to feed
    /// invalid content to `decode`), with correct length and CRC.
    pub fn raw_bytes(&self) -> Vec<u8> {
        let owned = self.owned();
        let p = owned.payload();
        let (laws, tree, balls) = p.tables.sections();
        let locations =
            PostcardSection::new(SectionKind::Locations, LocationsSection { K: p.K, P: p.P });
        let fallback = PostcardSection::new(
            SectionKind::Fallback,
            FallbackSection {
                fallback: p.fallback,
                input_box: p.input_box,
            },
        );
        let laws = PostcardSection::new(SectionKind::PwaLaws, laws);
        let tree = PostcardSection::new(SectionKind::PwaTree, tree);
        let balls = PostcardSection::new(SectionKind::PwaBalls, balls);
        let sections: [&dyn SectionWrite; 5] = [&locations, &fallback, &laws, &tree, &balls];
        let mut buf = vec![0u8; MAX_IMAGE_LEN + 4096];
        let len = write_image(
            &mut buf,
            Mode::PwaFeedback as u8,
            self.dims(),
            self.period,
            &sections,
        )
        .unwrap();
        buf.truncate(len);
        buf
    }

    /// The error `decode` reports for the raw bytes, checked against `Image::new_pwa` (which must report
    /// the same); `Err` says what went wrong instead.
    pub fn decode_err(&self) -> Result<ImageError, String> {
        let e = match shared_types::image::decode(&self.raw_bytes()) {
            Ok(_) => return Err("decode accepted the content".into()),
            Err(e) => e,
        };
        let owned = self.owned();
        let built = Image::new_pwa(self.dims(), self.period, owned.payload()).map(|_| ());
        if built != Err(e) {
            return Err(format!(
                "Image::new_pwa and decode disagree: {built:?} vs Err({e:?})"
            ));
        }
        Ok(e)
    }

    /// Reads the content back out of a decoded image through its accessors.
    pub fn from_image(img: &Image<'_>) -> PwaContent {
        let (n, m, nl, np) = (img.n(), img.m(), img.n_locations(), img.n_partitions());
        let nn = img.n_nodes();
        let mut c = PwaContent {
            n,
            m,
            nl,
            np,
            period: img.period(),
            K: vec![],
            P: vec![],
            gain: vec![],
            offset: vec![],
            depth: img.tree_depth() as u8,
            node_a: (0..nn)
                .flat_map(|i| (0..n).map(move |k| (i, k)))
                .map(|(i, k)| img.node_normal(i, k))
                .collect(),
            node_b: (0..nn).map(|i| img.node_offset(i)).collect(),
            node_child: (0..nn)
                .flat_map(|i| {
                    let (l, r) = img.node_children(i).unwrap();
                    [l.code().unwrap(), r.code().unwrap()]
                })
                .collect(),
            leaf_partition: (0..img.n_leaves())
                .map(|l| img.leaf_partition(l) as u16)
                .collect(),
            leaf_balls: (0..img.n_leaves())
                .map(|l| {
                    let (_, len) = img.leaf_refs(l);
                    (0..len)
                        .map(|k| img.leaf_ball(l, k).unwrap() as u16)
                        .collect()
                })
                .collect(),
            R: (0..nl * n * n)
                .map(|i| img.factor(i / (n * n), (i / n) % n, i % n))
                .collect(),
            ball_centre: (0..img.n_balls())
                .flat_map(|b| (0..n).map(move |i| (b, i)))
                .map(|(b, i)| img.ball_centre(b, i))
                .collect(),
            ball_centre_z: (0..img.n_balls())
                .flat_map(|b| (0..n).map(move |i| (b, i)))
                .map(|(b, i)| img.ball_centre_z(b, i))
                .collect(),
            ball_threshold: (0..img.n_balls()).map(|b| img.ball_threshold(b)).collect(),
            ball_location: (0..img.n_balls())
                .map(|b| img.ball_location(b) as u8)
                .collect(),
            ball_partition: (0..img.n_balls())
                .map(|b| img.ball_partition(b) as u16)
                .collect(),
            fallback: match img.fallback() {
                Fallback::Hold => FallbackC::Hold,
                Fallback::Zero => FallbackC::Zero,
                Fallback::Constant { .. } => {
                    FallbackC::Constant((0..m).map(|j| img.fallback_input(j)).collect())
                }
                Fallback::Linear { .. } => FallbackC::Linear {
                    K: (0..m)
                        .flat_map(|r| (0..n).map(move |c| (r, c)))
                        .map(|(r, c)| img.fallback_K(r, c))
                        .collect(),
                    x_ref: (0..n).map(|i| img.fallback_x_ref(i)).collect(),
                    u_ref: (0..m).map(|j| img.fallback_u_ref(j)).collect(),
                },
            },
            input_box: img.has_input_box().then(|| {
                let b: Vec<(f32, f32)> = (0..m).map(|j| img.input_bounds(j).unwrap()).collect();
                (
                    b.iter().map(|p| p.0).collect(),
                    b.iter().map(|p| p.1).collect(),
                )
            }),
            n_trajectories: img.n_trajectories(),
            counts: None,
        };
        for l in 0..nl {
            for r in 0..m {
                for col in 0..n {
                    c.K.push(img.K(l, r, col));
                }
            }
            for r in 0..n {
                for col in 0..n {
                    c.P.push(img.P(l, r, col));
                }
            }
        }
        for j in 0..np {
            for r in 0..m {
                for col in 0..n {
                    c.gain.push(img.law_gain(j, r, col));
                }
                c.offset.push(img.law_offset(j, r));
            }
        }
        c
    }

    /// Every root-to-terminal path of the tree: (the (node, went left) decisions, the terminal child).
    pub fn paths(&self) -> Vec<(Vec<(usize, bool)>, Child)> {
        let mut out = Vec::new();
        if self.node_b.is_empty() {
            out.push((vec![], Child::Leaf(0)));
            return out;
        }
        fn walk(
            c: &PwaContent,
            node: usize,
            path: &mut Vec<(usize, bool)>,
            out: &mut Vec<(Vec<(usize, bool)>, Child)>,
        ) {
            for (side, left) in [(0, true), (1, false)] {
                path.push((node, left));
                match Child::from_code(c.node_child[2 * node + side]) {
                    Child::Node(k) => walk(c, k as usize, path, out),
                    t => out.push((path.clone(), t)),
                }
                path.pop();
            }
        }
        walk(self, 0, &mut Vec::new(), &mut out);
        out
    }
}

/// Random parameters of a PWA content generator.
#[derive(Clone, Copy, Debug)]
pub struct PwaShape {
    pub max_n: usize,
    pub max_m: usize,
    pub max_partitions: usize,
    pub max_depth: usize,
    pub max_nodes: usize,
    /// Probability that a terminal child is OUTSIDE rather than a leaf.
    pub p_outside: f64,
    pub max_leaf_balls: usize,
    /// Centres, hyperplane offsets and states are drawn in [-box, box]^n.
    pub box_half: f32,
}

impl Default for PwaShape {
    fn default() -> Self {
        PwaShape {
            max_n: 4,
            max_m: 3,
            max_partitions: 6,
            max_depth: 6,
            max_nodes: 40,
            p_outside: 0.15,
            max_leaf_balls: 6,
            box_half: 3.0,
        }
    }
}

/// A random valid PWA content: a random tree (nodes in preorder, so children come after parents), leaves
/// with random partitions, each listing balls of its own partition.
pub fn random_pwa(rng: &mut ChaCha8Rng, s: PwaShape) -> PwaContent {
    let n = rng.random_range(1..=s.max_n);
    let m = rng.random_range(1..=s.max_m);
    let nl = rng.random_range(1..=2);
    let np = rng.random_range(1..=s.max_partitions);
    let mut u =
        |k: usize, a: f32| -> Vec<f32> { (0..k).map(|_| rng.random_range(-a..a)).collect() };
    let K = u(nl * m * n, 3.0);
    let gain = u(np * m * n, 3.0);
    let offset = u(np * m, 5.0);
    let fb_K = u(m * n, 2.0);
    let x_ref = u(n, 1.0);
    let u_ref = u(m, 1.0);
    let P: Vec<f32> = (0..nl)
        .flat_map(|_| {
            let p = random_spd(rng, n);
            // Scale to unit-ish size so that balls of radius ~1 are ~unit-sized.
            let s = 1.0 / n as f32;
            p.into_iter().map(move |v| v * s).collect::<Vec<_>>()
        })
        .collect();

    // Tree, in preorder (so children come after parents).
    struct TreeGen<'r> {
        rng: &'r mut ChaCha8Rng,
        s: PwaShape,
        n: usize,
        node_a: Vec<f32>,
        node_b: Vec<f32>,
        node_child: Vec<u16>,
        n_leaves: u16,
    }
    impl TreeGen<'_> {
        fn child(&mut self, level: usize, root: bool) -> u16 {
            let room = self.node_b.len() < self.s.max_nodes && level < self.s.max_depth;
            let split = room && (root || self.rng.random_bool(0.6));
            if !split {
                if !root && self.rng.random_bool(self.s.p_outside) {
                    return OUTSIDE;
                }
                self.n_leaves += 1;
                return LEAF_BASE + (self.n_leaves - 1);
            }
            let me = self.node_b.len();
            let a: Vec<f32> = loop {
                let a: Vec<f32> = (0..self.n)
                    .map(|_| self.rng.random_range(-1.0f32..1.0))
                    .collect();
                if a.iter().any(|&v| v != 0.0) {
                    break a;
                }
            };
            self.node_a.extend_from_slice(&a);
            let h = self.s.box_half * 0.7;
            self.node_b.push(self.rng.random_range(-h..h));
            self.node_child.extend_from_slice(&[0, 0]);
            for side in 0..2 {
                let c = self.child(level + 1, false);
                self.node_child[2 * me + side] = c;
            }
            me as u16
        }
    }
    let root_leaf_only = rng.random_bool(0.05);
    let mut g = TreeGen {
        rng: &mut *rng,
        s,
        n,
        node_a: Vec::new(),
        node_b: Vec::new(),
        node_child: Vec::new(),
        n_leaves: 0,
    };
    if !root_leaf_only {
        g.child(0, true);
    }
    let TreeGen {
        node_a,
        node_b,
        mut node_child,
        mut n_leaves,
        ..
    } = g;
    if n_leaves == 0 {
        // Every terminal came out OUTSIDE (or there is no tree): make the last OUTSIDE a leaf.
        if let Some(c) = node_child.iter_mut().rev().find(|c| **c == OUTSIDE) {
            *c = LEAF_BASE;
        }
        n_leaves = 1;
    }
    let leaf_partition: Vec<u16> = (0..n_leaves)
        .map(|_| rng.random_range(0..np as u16))
        .collect();

    // Balls: per partition a pool; each leaf lists a random subset of its partition's pool.
    let mut ball_centre = Vec::new();
    let mut ball_threshold = Vec::new();
    let mut ball_location = Vec::new();
    let mut ball_partition = Vec::new();
    let mut pools: Vec<Vec<u16>> = vec![Vec::new(); np];
    let mut leaf_balls = Vec::new();
    for &j in &leaf_partition {
        let k = rng.random_range(1..=s.max_leaf_balls);
        let mut listed = Vec::new();
        for _ in 0..k {
            let pool = &mut pools[j as usize];
            if !pool.is_empty() && rng.random_bool(0.3) {
                listed.push(pool[rng.random_range(0..pool.len())]);
            } else {
                let b = ball_threshold.len() as u16;
                ball_centre.extend((0..n).map(|_| rng.random_range(-s.box_half..s.box_half)));
                let r = rng.random_range(0.3f32..2.0);
                ball_threshold.push(r * r);
                ball_location.push(rng.random_range(0..nl as u8));
                ball_partition.push(j);
                pool.push(b);
                listed.push(b);
            }
        }
        leaf_balls.push(listed);
    }
    let depth = tree_depth(&node_child);
    let fallback = match rng.random_range(0..3) {
        0 => FallbackC::Hold,
        1 => FallbackC::Zero,
        _ => FallbackC::Linear {
            K: fb_K,
            x_ref,
            u_ref,
        },
    };
    let input_box = rng.random_bool(0.5).then(|| {
        let lo: Vec<f32> = (0..m).map(|_| rng.random_range(-5.0..0.0)).collect();
        let hi: Vec<f32> = (0..m).map(|_| rng.random_range(0.0..5.0)).collect();
        (lo, hi)
    });
    assert!(node_b.len() <= MAX_TREE_NODES && (depth as usize) <= MAX_TREE_DEPTH);
    PwaContent {
        n,
        m,
        nl,
        np,
        period: rng.random_range(0.001..1.0),
        K,
        P,
        gain,
        offset,
        depth,
        node_a,
        node_b,
        node_child,
        leaf_partition,
        leaf_balls,
        R: vec![],
        ball_centre,
        ball_centre_z: vec![],
        ball_threshold,
        ball_location,
        ball_partition,
        fallback,
        input_box,
        n_trajectories: 0,
        counts: None,
    }
    .whitened()
}

pub const L0: u16 = LEAF_BASE;
pub const L1: u16 = LEAF_BASE + 1;

/// n = 2, m = 1, one location (P = I), two partitions:
/// * law 0: `u = −x₀ − 2x₁ + 0.5`; law 1: `u = −3x₀ − 1`;
/// * node 0: `x₀ ≤ 0` → node 1, else leaf 1 (partition 1);
/// * node 1: `x₁ ≤ 2` → leaf 0 (partition 0), else OUTSIDE;
/// * balls: 0 at (−1, 0) δ 1 and 1 at (−0.5, 1) δ 0.75 for partition 0; 2 at (1, 0) δ 1.5 for partition 1
///   (stored thresholds δ²: 1, 0.5625, 2.25);
///   leaf 0 lists 0 and 1, leaf 1 lists 2.
pub fn two_partitions() -> PwaContent {
    PwaContent {
        n: 2,
        m: 1,
        nl: 1,
        np: 2,
        period: 0.05,
        K: vec![-1.0, -1.0],
        P: vec![1.0, 0.0, 0.0, 1.0],
        gain: vec![-1.0, -2.0, -3.0, 0.0],
        offset: vec![0.5, -1.0],
        depth: 2,
        node_a: vec![1.0, 0.0, 0.0, 1.0],
        node_b: vec![0.0, 2.0],
        node_child: vec![1, L1, L0, OUTSIDE],
        leaf_partition: vec![0, 1],
        leaf_balls: vec![vec![0, 1], vec![2]],
        R: vec![1.0, 0.0, 0.0, 1.0],
        ball_centre: vec![-1.0, 0.0, -0.5, 1.0, 1.0, 0.0],
        ball_centre_z: vec![-1.0, 0.0, -0.5, 1.0, 1.0, 0.0],
        ball_threshold: vec![1.0, 0.5625, 2.25],
        ball_location: vec![0, 0, 0],
        ball_partition: vec![0, 0, 1],
        fallback: FallbackC::Linear {
            K: vec![-0.5, -0.5],
            x_ref: vec![0.0, 0.0],
            u_ref: vec![0.0],
        },
        input_box: Some((vec![-2.0], vec![2.0])),
        n_trajectories: 0,
        counts: None,
    }
}
