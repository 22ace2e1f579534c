//! Little-endian views of the image's byte strings and the total helpers every validator uses: reads that
//! give 0 instead of panicking out of range (validated images never take that path), saturating
//! conversions, and the field checks (dimension ranges, byte lengths, finite floats, positive
//! definiteness) shared by the image and the PWA tables.

#![allow(non_snake_case)]

use crate::capacity::MAX_N;
use crate::error::{Dim, Field, ImageError, Pos};

#[inline(always)]
pub(crate) fn f32_at(bytes: &[u8], i: usize) -> f32 {
    let Some(s) = i.checked_mul(4) else {
        return 0.0;
    };
    match bytes.get(s..s.wrapping_add(4)) {
        Some(&[a, b, c, d]) => f32::from_le_bytes([a, b, c, d]),
        _ => 0.0,
    }
}

#[inline(always)]
pub(crate) fn u32_at(bytes: &[u8], i: usize) -> u32 {
    let Some(s) = i.checked_mul(4) else { return 0 };
    match bytes.get(s..s.wrapping_add(4)) {
        Some(&[a, b, c, d]) => u32::from_le_bytes([a, b, c, d]),
        _ => 0,
    }
}

#[inline(always)]
pub(crate) fn u16_at(bytes: &[u8], off: usize) -> u16 {
    match bytes.get(off..off.saturating_add(2)) {
        Some(&[a, b]) => u16::from_le_bytes([a, b]),
        _ => 0,
    }
}

/// `bytes[4*start .. 4*(start+len)]`, or an empty slice if out of range.
#[inline(always)]
pub(crate) fn f32_span(bytes: &[u8], start: usize, len: usize) -> &[u8] {
    let s = start.saturating_mul(4);
    let e = start.saturating_add(len).saturating_mul(4);
    bytes.get(s..e).unwrap_or(&[])
}

/// Little-endian `f32` values of a byte string (a trailing partial value is ignored).
#[inline(always)]
pub(crate) fn floats(bytes: &[u8]) -> impl Iterator<Item = f32> + '_ {
    // A pattern, not `c[0]..c[3]`: the closure may be compiled out of line (e.g. under `all`'s
    // `try_fold`), where the chunk length is unknown and indexing links a bounds-check panic. Chunks
    // are always 4 bytes long, so the other arm is never taken.
    bytes.chunks_exact(4).map(|c| match *c {
        [a, b, c, d] => f32::from_le_bytes([a, b, c, d]),
        _ => 0.0,
    })
}

/// Little-endian `u16` number `i` of a byte string; 0 out of range.
#[inline(always)]
pub(crate) fn u16_le(bytes: &[u8], i: usize) -> u16 {
    u16_at(bytes, i.saturating_mul(2))
}

/// `a / b`, 0 if `b` is 0 (total, so position reporting has no panic path).
pub(crate) fn div(a: usize, b: usize) -> usize {
    a.checked_div(b).unwrap_or(0)
}

/// `a % b`, 0 if `b` is 0.
pub(crate) fn rem(a: usize, b: usize) -> usize {
    a.checked_rem(b).unwrap_or(0)
}

pub(crate) fn sat16(v: usize) -> u16 {
    u16::try_from(v).unwrap_or(u16::MAX)
}

pub(crate) fn sat32(v: usize) -> u32 {
    u32::try_from(v).unwrap_or(u32::MAX)
}

pub(crate) fn check_dim(dim: Dim, value: usize, min: usize, max: usize) -> Result<(), ImageError> {
    if value < min || value > max {
        Err(ImageError::DimOutOfRange {
            dim,
            value: sat32(value),
            min: sat32(min),
            max: sat32(max),
        })
    } else {
        Ok(())
    }
}

pub(crate) fn check_len(field: Field, bytes: &[u8], expected: usize) -> Result<(), ImageError> {
    if bytes.len() != expected {
        Err(ImageError::FieldLength {
            field,
            expected: sat32(expected),
            found: sat32(bytes.len()),
        })
    } else {
        Ok(())
    }
}

/// Checks that every `f32` in `bytes` is finite; `pos(i)` maps the flat index to a position.
pub(crate) fn check_finite(
    field: Field,
    bytes: &[u8],
    pos: impl Fn(usize) -> Pos,
) -> Result<(), ImageError> {
    for (i, x) in floats(bytes).enumerate() {
        if !x.is_finite() {
            return Err(ImageError::NonFinite { field, pos: pos(i) });
        }
    }
    Ok(())
}

/// Positive definiteness of a symmetric n×n matrix (n ≤ MAX_N) by an LDLᵀ factorisation without pivoting,
/// in f64 so that the verdict on the stored f32 values is not itself an f32 rounding artefact. The matrix
/// is positive definite iff every pivot d_j is positive. Hand-written: it is a dozen lines, runs once per
/// location at decode, and must be no_std without allocation.
pub(crate) fn positive_definite(p: &[u8], n: usize) -> bool {
    let mut L = [[0.0f64; MAX_N]; MAX_N];
    let mut d = [0.0f64; MAX_N];
    let n = n.min(MAX_N);
    for j in 0..n {
        let mut dj = f32_at(p, j * n + j) as f64;
        for k in 0..j {
            dj -= L[j][k] * L[j][k] * d[k];
        }
        let pivot_ok = dj.is_finite() && dj > 0.0;
        if !pivot_ok {
            return false;
        }
        d[j] = dj;
        for i in (j + 1)..n {
            let mut s = f32_at(p, i * n + j) as f64;
            for k in 0..j {
                s -= L[i][k] * L[j][k] * d[k];
            }
            L[i][j] = s / dj;
        }
    }
    true
}

/// Little-endian `u32` at byte offset `off`; 0 out of range.
#[inline(always)]
pub(crate) fn u32_at_byte(bytes: &[u8], off: usize) -> u32 {
    match bytes.get(off..off.saturating_add(4)) {
        Some(&[a, b, c, d]) => u32::from_le_bytes([a, b, c, d]),
        _ => 0,
    }
}
