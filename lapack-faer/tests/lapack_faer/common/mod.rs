//! Shared helpers for the lapack-faer tests: seeded random matrices in padded column-major storage and
//! straightforward reference algorithms (triple loops, cyclic Jacobi) to compare against.
#![allow(dead_code)]

use core::ffi::c_char;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Value written into padding rows (beyond the logical row count) to detect out-of-bounds reads and writes.
pub const PAD: f64 = 7777.0;

pub fn ch(c: u8) -> c_char {
    c as c_char
}

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// A random `m × n` matrix stored column-major with leading dimension `ld >= m`; padding holds [`PAD`].
pub fn rand_mat(r: &mut ChaCha8Rng, m: usize, n: usize, ld: usize) -> Vec<f64> {
    let mut v = vec![PAD; ld * n.max(1)];
    for j in 0..n {
        for i in 0..m {
            v[i + j * ld] = r.random_range(-1.0..1.0);
        }
    }
    v
}

/// A random symmetric positive definite `n × n` matrix (`G Gᵀ + n I`), dense, leading dimension `ld`.
pub fn rand_spd(r: &mut ChaCha8Rng, n: usize, ld: usize) -> Vec<f64> {
    let g = rand_mat(r, n, n, n);
    let mut a = vec![PAD; ld * n];
    for j in 0..n {
        for i in 0..n {
            let mut s = if i == j { n as f64 } else { 0.0 };
            for k in 0..n {
                s += g[i + k * n] * g[j + k * n];
            }
            a[i + j * ld] = s;
        }
    }
    a
}

/// A random symmetric `n × n` matrix, dense, leading dimension `ld`.
pub fn rand_sym(r: &mut ChaCha8Rng, n: usize, ld: usize) -> Vec<f64> {
    let mut a = rand_mat(r, n, n, ld);
    for j in 0..n {
        for i in 0..j {
            a[j + i * ld] = a[i + j * ld];
        }
    }
    a
}

pub fn at(a: &[f64], ld: usize, i: usize, j: usize) -> f64 {
    a[i + j * ld]
}

/// `op(X)[i, j]` for a column-major `X` with leading dimension `ld`.
pub fn op_at(x: &[f64], ld: usize, trans: bool, i: usize, j: usize) -> f64 {
    if trans {
        x[j + i * ld]
    } else {
        x[i + j * ld]
    }
}

/// Dense product `A B` of column-major matrices (`A` m×k, `B` k×n), contiguous result.
pub fn naive_mul(
    a: &[f64],
    lda: usize,
    b: &[f64],
    ldb: usize,
    m: usize,
    k: usize,
    n: usize,
) -> Vec<f64> {
    let mut c = vec![0.0; m * n];
    for j in 0..n {
        for i in 0..m {
            let mut s = 0.0;
            for l in 0..k {
                s += a[i + l * lda] * b[l + j * ldb];
            }
            c[i + j * m] = s;
        }
    }
    c
}

/// Eigenvalues of a symmetric matrix by the cyclic Jacobi method (ascending), the textbook reference.
pub fn jacobi_eigenvalues(a: &[f64], ld: usize, n: usize) -> Vec<f64> {
    let mut m = vec![0.0; n * n];
    for j in 0..n {
        for i in 0..n {
            m[i + j * n] = a[i + j * ld];
        }
    }
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|j| (0..n).map(move |i| (i, j)))
            .filter(|(i, j)| i != j)
            .map(|(i, j)| m[i + j * n].powi(2))
            .sum();
        if off < 1e-30 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = m[p + q * n];
                if apq.abs() < 1e-300 {
                    continue;
                }
                let theta = (m[q + q * n] - m[p + p * n]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let mkp = m[k + p * n];
                    let mkq = m[k + q * n];
                    m[k + p * n] = c * mkp - s * mkq;
                    m[k + q * n] = s * mkp + c * mkq;
                }
                for k in 0..n {
                    let mpk = m[p + k * n];
                    let mqk = m[q + k * n];
                    m[p + k * n] = c * mpk - s * mqk;
                    m[q + k * n] = s * mpk + c * mqk;
                }
            }
        }
    }
    let mut ev: Vec<f64> = (0..n).map(|i| m[i + i * n]).collect();
    ev.sort_by(|a, b| a.partial_cmp(b).unwrap());
    ev
}

pub fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}
