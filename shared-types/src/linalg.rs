//! The evaluator's matrix–vector products on nalgebra's no_std matrix views over the image's own f32
//! data: the affine law `u = A x + b` (the feedforward law, the PWA law and the linear fallback) and the
//! quadratic form `eᵀ P e` of the ball selection.
//!
//! The image stores its matrices row-major as little-endian f32 inside postcard byte strings, so a matrix
//! starts at any byte offset and a `&[f32]` cannot borrow it. The views hold the 4-byte words instead
//! (`[u8; 4]`, alignment 1): a row-major `r × c` matrix is the column-major `c × r` view of its
//! transpose, so row i is the view's column i, borrowed from the image without a copy, and each word is
//! read with `f32::from_le_bytes` as the product uses it.
//!
//! Summation order: a row times a vector is nalgebra's `zip_fold` from 0, so `((0 + p₀) + p₁) + … +
//! p_{n−1}` with `pⱼ = aⱼxⱼ` rounded to f32 before the add (no fused multiply-add: the Cortex-M4F's
//! `VMLA.F32` rounds the product first). The law then adds its offset, `(A x)ᵢ + bᵢ`; the quadratic form
//! is `((0 + e₀s₀) + e₁s₁) + …` with `sᵢ = (P e)ᵢ` in the row order above. The C export's evaluator
//! (`host-compiler/src/export/c/`) performs the same operations in the same order.
//!
//! The selection of a one-location image of a small fixed dimension reads P once into f32 rows
//! ([`matrix_fixed`]) and runs [`quadratic_form_fixed`] per ball: the same operations in the same order,
//! unrolled, P held in registers across the balls.
//!
//! Why not nalgebra's `dot`/`gemv`: they need an f32 element type, so every row would first be copied
//! out of the image into an aligned buffer. Measured under QEMU with that copy (hil-bench, worst step):
//! the feedforward step 1280 → 2280 instructions (+78 %), the hybrid step 920 → 1320 (+43 %), the
//! model-maps step 5280 → 6280 (+19 %); with these views: 1320, 880 and 5320.
#![allow(non_snake_case)]

use crate::capacity::{MAX_M, MAX_N};
use crate::raw::floats;
use nalgebra::{DMatrixView, DVectorView, Dyn, Matrix, RawStorage, U1};

/// The little-endian f32 of `bytes` as 4-byte words (a trailing partial word is ignored).
#[inline(always)]
fn words(bytes: &[u8]) -> &[[u8; 4]] {
    bytes.as_chunks::<4>().0
}

/// `row · x`, left to right from 0 (module doc), for a view of little-endian words and an f32 vector of
/// the same length.
#[inline(always)]
fn dot<S>(row: &Matrix<[u8; 4], Dyn, U1, S>, x: &DVectorView<'_, f32>) -> f32
where
    S: RawStorage<[u8; 4], Dyn, U1>,
{
    row.zip_fold(x, 0.0, |s, a, b| s + f32::from_le_bytes(a) * b)
}

/// `out_i = (A x)_i + b_i`, i < m, for the row-major `m × n` matrix `A` and the offsets `b` (m values),
/// both little-endian bytes; `out` past m is left alone, and nothing is written if `A` or `x` is too
/// short (never for a validated image).
#[inline(never)]
pub(crate) fn affine(A: &[u8], x: &[f32], b: &[u8], n: usize, m: usize, out: &mut [f32; MAX_M]) {
    let (Some(x), Some(a)) = (x.get(..n), words(A).get(..n * m)) else {
        return;
    };
    let x = DVectorView::from_slice(x, n);
    let At = DMatrixView::from_slice(a, n, m);
    for ((o, row), bi) in out.iter_mut().zip(At.column_iter()).zip(floats(b)) {
        *o = dot(&row, &x) + bi;
    }
}

/// `eᵀ P e` for the row-major `n × n` matrix `P` (little-endian bytes) and the first n values of `e`; 0
/// if `P` is too short (never for a validated image).
#[inline(never)]
pub(crate) fn quadratic_form(P: &[u8], e: &[f32; MAX_N], n: usize) -> f32 {
    let (Some(e), Some(p)) = (e.get(..n), words(P).get(..n * n)) else {
        return 0.0;
    };
    let ev = DVectorView::from_slice(e, n);
    let P = DMatrixView::from_slice(p, n, n);
    let mut d2 = 0.0f32;
    for (row, &ei) in P.column_iter().zip(e) {
        d2 += ei * dot(&row, &ev);
    }
    d2
}

/// The row-major `N × N` matrix `P` (little-endian bytes) as f32 rows; zeros if `P` is too short (never
/// for a validated image).
#[inline(always)]
pub(crate) fn matrix_fixed<const N: usize>(P: &[u8]) -> [[f32; N]; N] {
    let mut out = [[0.0f32; N]; N];
    if let Some(p) = words(P).get(..N * N) {
        for (row, w) in out.iter_mut().zip(p.chunks_exact(N)) {
            for (a, b) in row.iter_mut().zip(w) {
                *a = f32::from_le_bytes(*b);
            }
        }
    }
    out
}

/// [`quadratic_form`] for a matrix already read ([`matrix_fixed`]) and a fixed dimension N: the same
/// operations in the same order (module doc), unrolled, with P in registers across calls in a loop.
#[inline(always)]
pub(crate) fn quadratic_form_fixed<const N: usize>(P: &[[f32; N]; N], e: &[f32; N]) -> f32 {
    let mut d2 = 0.0f32;
    for (row, &ei) in P.iter().zip(e) {
        let mut s = 0.0f32;
        for (&a, &ej) in row.iter().zip(e) {
            s += a * ej;
        }
        d2 += ei * s;
    }
    d2
}
