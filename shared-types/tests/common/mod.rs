//! Test helpers: an owned, std-side description of image content, its conversion to bytes, and a seeded
//! generator of random valid contents.
#![allow(dead_code, non_snake_case)]

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use shared_types::capacity::MAX_IMAGE_LEN;
use shared_types::image::{
    encode, Dims, Fallback, Image, ImageError, InputBox, Mode, Payload, Terminal,
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
    pub traj_end: Vec<u8>,
    pub centre: Vec<u8>,
    pub delta: Vec<u8>,
    pub v: Vec<u8>,
    pub location: Vec<u8>,
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
            traj_end: &self.traj_end,
            centre: &self.centre,
            delta: &self.delta,
            v: &self.v,
            location: &self.location,
            fallback: match (&self.fb, self.fb_kind) {
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

    pub fn owned(&self) -> Owned {
        let mut ends = Vec::new();
        let mut acc = 0u32;
        for &l in &self.traj_len {
            acc += l as u32;
            ends.extend_from_slice(&acc.to_le_bytes());
        }
        Owned {
            K: le(&self.K),
            P: le(&self.P),
            traj_end: ends,
            centre: le(&self.centre),
            delta: le(&self.delta),
            v: le(&self.v),
            location: self.location.clone(),
            fb: match &self.fallback {
                FallbackC::Linear { K, x_ref, u_ref } => Some((le(K), le(x_ref), le(u_ref))),
                _ => None,
            },
            fb_kind: match self.fallback {
                FallbackC::Hold => 0,
                FallbackC::Zero => 1,
                FallbackC::Linear { .. } => 2,
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
