//! Level-2/3 BLAS routines (`?gemm`, `?gemv`, `?symv`, `?syrk`, `?syr2k`) with reference-BLAS semantics,
//! computed with faer's (triangular) matrix products.
//!
//! Semantics kept from reference BLAS:
//! - argument checks in the documented order, reported through [`xerbla`] (printed, not fatal);
//! - the quick returns, and `beta == 0` meaning "C/y is not read" (NaNs there do not propagate);
//! - `alpha == 0` meaning "A/B/x are not read";
//! - `?syrk`/`?syr2k`/`?symv` read and write only the `uplo` triangle.

use crate::scalar::*;
use core::ffi::c_char;
use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::reborrow::*;
use faer::{Accum, MatMut, Par};

/// `C ← beta·C` on the whole matrix, writing zeros (not `0·C`) when `beta == 0`.
fn scale_full<T: Real>(mut c: MatMut<'_, T>, beta: T) {
    if beta == T::ONE {
        return;
    }
    for j in 0..c.ncols() {
        for i in 0..c.nrows() {
            c[(i, j)] = if beta == T::ZERO {
                T::ZERO
            } else {
                beta * c[(i, j)]
            };
        }
    }
}

/// `C ← beta·C` on the upper or lower triangle (diagonal included) only.
fn scale_tri<T: Real>(mut c: MatMut<'_, T>, upper: bool, beta: T) {
    if beta == T::ONE {
        return;
    }
    let n = c.nrows();
    for j in 0..n {
        let rows = if upper { 0..j + 1 } else { j..n };
        for i in rows {
            c[(i, j)] = if beta == T::ZERO {
                T::ZERO
            } else {
                beta * c[(i, j)]
            };
        }
    }
}

/// `?gemm`: `C ← alpha·op(A)·op(B) + beta·C`, `op(X) ∈ {X, Xᵀ}`.
///
/// # Safety
/// Fortran calling convention: every pointer valid for the sizes the arguments describe.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn gemm<T: Real>(
    name: &str,
    transa: *const c_char,
    transb: *const c_char,
    m: *const i32,
    n: *const i32,
    k: *const i32,
    alpha: *const T,
    a: *const T,
    lda: *const i32,
    b: *const T,
    ldb: *const i32,
    beta: *const T,
    c: *mut T,
    ldc: *const i32,
) {
    let (ta, tb) = unsafe { (flag(transa), flag(transb)) };
    let (m, n, k) = unsafe { (int(m), int(n), int(k)) };
    let (lda, ldb, ldc) = unsafe { (int(lda), int(ldb), int(ldc)) };
    let nota = ta == b'N';
    let notb = tb == b'N';
    let nrowa = if nota { m } else { k };
    let nrowb = if notb { k } else { n };
    let info = if !matches!(ta, b'N' | b'T' | b'C') {
        1
    } else if !matches!(tb, b'N' | b'T' | b'C') {
        2
    } else if m < 0 {
        3
    } else if n < 0 {
        4
    } else if k < 0 {
        5
    } else if lda < max1(nrowa) {
        8
    } else if ldb < max1(nrowb) {
        10
    } else if ldc < max1(m) {
        13
    } else {
        0
    };
    if info != 0 {
        xerbla(name, info);
        return;
    }
    let (alpha, beta) = unsafe { (val(alpha), val(beta)) };
    if m == 0 || n == 0 || ((alpha == T::ZERO || k == 0) && beta == T::ONE) {
        return;
    }
    let (m, n, k) = (m as usize, n as usize, k as usize);
    let mut cm = unsafe { mat_mut(c, m, n, ldc as usize) };
    if alpha == T::ZERO || k == 0 {
        scale_full(cm, beta);
        return;
    }
    let am = if nota {
        unsafe { mat_ref(a, m, k, lda as usize) }
    } else {
        unsafe { mat_ref(a, k, m, lda as usize) }.transpose()
    };
    let bm = if notb {
        unsafe { mat_ref(b, k, n, ldb as usize) }
    } else {
        unsafe { mat_ref(b, n, k, ldb as usize) }.transpose()
    };
    let accum = if beta == T::ZERO {
        Accum::Replace
    } else {
        scale_full(cm.rb_mut(), beta);
        Accum::Add
    };
    matmul(cm, accum, am, bm, alpha, Par::Seq);
}

/// `?gemv`: `y ← alpha·op(A)·x + beta·y`.
///
/// # Safety
/// Fortran calling convention: every pointer valid for the sizes the arguments describe.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn gemv<T: Real>(
    name: &str,
    trans: *const c_char,
    m: *const i32,
    n: *const i32,
    alpha: *const T,
    a: *const T,
    lda: *const i32,
    x: *const T,
    incx: *const i32,
    beta: *const T,
    y: *mut T,
    incy: *const i32,
) {
    let t = unsafe { flag(trans) };
    let (m, n, lda, incx, incy) = unsafe { (int(m), int(n), int(lda), int(incx), int(incy)) };
    let info = if !matches!(t, b'N' | b'T' | b'C') {
        1
    } else if m < 0 {
        2
    } else if n < 0 {
        3
    } else if lda < max1(m) {
        6
    } else if incx == 0 {
        8
    } else if incy == 0 {
        11
    } else {
        0
    };
    if info != 0 {
        xerbla(name, info);
        return;
    }
    let (alpha, beta) = unsafe { (val(alpha), val(beta)) };
    if m == 0 || n == 0 || (alpha == T::ZERO && beta == T::ONE) {
        return;
    }
    let (m, n) = (m as usize, n as usize);
    let (lenx, leny) = if t == b'N' { (n, m) } else { (m, n) };
    let mut yv = unsafe { vec_mut(y, leny, incy) };
    scale_full(yv.rb_mut().as_mat_mut(), beta);
    if alpha == T::ZERO {
        return;
    }
    let xv = unsafe { vec_ref(x, lenx, incx) };
    let am = unsafe { mat_ref(a, m, n, lda as usize) };
    let op = if t == b'N' { am } else { am.transpose() };
    matmul(
        yv.as_mat_mut(),
        Accum::Add,
        op,
        xv.as_mat(),
        alpha,
        Par::Seq,
    );
}

/// `?symv`: `y ← alpha·A·x + beta·y` with `A` symmetric, only its `uplo` triangle read.
///
/// # Safety
/// Fortran calling convention: every pointer valid for the sizes the arguments describe.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn symv<T: Real>(
    name: &str,
    uplo: *const c_char,
    n: *const i32,
    alpha: *const T,
    a: *const T,
    lda: *const i32,
    x: *const T,
    incx: *const i32,
    beta: *const T,
    y: *mut T,
    incy: *const i32,
) {
    let u = unsafe { flag(uplo) };
    let (n, lda, incx, incy) = unsafe { (int(n), int(lda), int(incx), int(incy)) };
    let info = if !matches!(u, b'U' | b'L') {
        1
    } else if n < 0 {
        2
    } else if lda < max1(n) {
        5
    } else if incx == 0 {
        7
    } else if incy == 0 {
        10
    } else {
        0
    };
    if info != 0 {
        xerbla(name, info);
        return;
    }
    let (alpha, beta) = unsafe { (val(alpha), val(beta)) };
    if n == 0 || (alpha == T::ZERO && beta == T::ONE) {
        return;
    }
    let n = n as usize;
    let mut yv = unsafe { vec_mut(y, n, incy) };
    scale_full(yv.rb_mut().as_mat_mut(), beta);
    if alpha == T::ZERO {
        return;
    }
    let xv = unsafe { vec_ref(x, n, incx) };
    let am = unsafe { mat_ref(a, n, n, lda as usize) };
    // A = tri(A) + strict_tri(A)ᵀ for the stored triangle: two triangular products, nothing else read.
    let (tri, strict_t) = if u == b'U' {
        (
            BlockStructure::TriangularUpper,
            BlockStructure::StrictTriangularLower,
        )
    } else {
        (
            BlockStructure::TriangularLower,
            BlockStructure::StrictTriangularUpper,
        )
    };
    let rect = BlockStructure::Rectangular;
    triangular::matmul(
        yv.rb_mut().as_mat_mut(),
        rect,
        Accum::Add,
        am,
        tri,
        xv.as_mat(),
        rect,
        alpha,
        Par::Seq,
    );
    triangular::matmul(
        yv.as_mat_mut(),
        rect,
        Accum::Add,
        am.transpose(),
        strict_t,
        xv.as_mat(),
        rect,
        alpha,
        Par::Seq,
    );
}

/// `?syrk`: `C ← alpha·op(A)·op(A)ᵀ + beta·C` on the `uplo` triangle, `op(A)` being `A` (n×k) or `Aᵀ` (A k×n).
///
/// # Safety
/// Fortran calling convention: every pointer valid for the sizes the arguments describe.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn syrk<T: Real>(
    name: &str,
    uplo: *const c_char,
    trans: *const c_char,
    n: *const i32,
    k: *const i32,
    alpha: *const T,
    a: *const T,
    lda: *const i32,
    beta: *const T,
    c: *mut T,
    ldc: *const i32,
) {
    let (u, t) = unsafe { (flag(uplo), flag(trans)) };
    let (n, k, lda, ldc) = unsafe { (int(n), int(k), int(lda), int(ldc)) };
    let nrowa = if t == b'N' { n } else { k };
    let info = if !matches!(u, b'U' | b'L') {
        1
    } else if !matches!(t, b'N' | b'T' | b'C') {
        2
    } else if n < 0 {
        3
    } else if k < 0 {
        4
    } else if lda < max1(nrowa) {
        7
    } else if ldc < max1(n) {
        10
    } else {
        0
    };
    if info != 0 {
        xerbla(name, info);
        return;
    }
    let (alpha, beta) = unsafe { (val(alpha), val(beta)) };
    if n == 0 || ((alpha == T::ZERO || k == 0) && beta == T::ONE) {
        return;
    }
    let (n, k) = (n as usize, k as usize);
    let upper = u == b'U';
    let mut cm = unsafe { mat_mut(c, n, n, ldc as usize) };
    if alpha == T::ZERO || k == 0 {
        scale_tri(cm, upper, beta);
        return;
    }
    let op = if t == b'N' {
        unsafe { mat_ref(a, n, k, lda as usize) }
    } else {
        unsafe { mat_ref(a, k, n, lda as usize) }.transpose()
    };
    let accum = if beta == T::ZERO {
        Accum::Replace
    } else {
        scale_tri(cm.rb_mut(), upper, beta);
        Accum::Add
    };
    let dst = if upper {
        BlockStructure::TriangularUpper
    } else {
        BlockStructure::TriangularLower
    };
    let rect = BlockStructure::Rectangular;
    triangular::matmul(
        cm,
        dst,
        accum,
        op,
        rect,
        op.transpose(),
        rect,
        alpha,
        Par::Seq,
    );
}

/// `?syr2k`: `C ← alpha·(op(A)·op(B)ᵀ + op(B)·op(A)ᵀ) + beta·C` on the `uplo` triangle.
///
/// # Safety
/// Fortran calling convention: every pointer valid for the sizes the arguments describe.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn syr2k<T: Real>(
    name: &str,
    uplo: *const c_char,
    trans: *const c_char,
    n: *const i32,
    k: *const i32,
    alpha: *const T,
    a: *const T,
    lda: *const i32,
    b: *const T,
    ldb: *const i32,
    beta: *const T,
    c: *mut T,
    ldc: *const i32,
) {
    let (u, t) = unsafe { (flag(uplo), flag(trans)) };
    let (n, k, lda, ldb, ldc) = unsafe { (int(n), int(k), int(lda), int(ldb), int(ldc)) };
    let nrowa = if t == b'N' { n } else { k };
    let info = if !matches!(u, b'U' | b'L') {
        1
    } else if !matches!(t, b'N' | b'T' | b'C') {
        2
    } else if n < 0 {
        3
    } else if k < 0 {
        4
    } else if lda < max1(nrowa) {
        7
    } else if ldb < max1(nrowa) {
        9
    } else if ldc < max1(n) {
        12
    } else {
        0
    };
    if info != 0 {
        xerbla(name, info);
        return;
    }
    let (alpha, beta) = unsafe { (val(alpha), val(beta)) };
    if n == 0 || ((alpha == T::ZERO || k == 0) && beta == T::ONE) {
        return;
    }
    let (n, k) = (n as usize, k as usize);
    let upper = u == b'U';
    let mut cm = unsafe { mat_mut(c, n, n, ldc as usize) };
    if alpha == T::ZERO || k == 0 {
        scale_tri(cm, upper, beta);
        return;
    }
    let (opa, opb) = if t == b'N' {
        unsafe {
            (
                mat_ref(a, n, k, lda as usize),
                mat_ref(b, n, k, ldb as usize),
            )
        }
    } else {
        unsafe {
            (
                mat_ref(a, k, n, lda as usize).transpose(),
                mat_ref(b, k, n, ldb as usize).transpose(),
            )
        }
    };
    let accum = if beta == T::ZERO {
        Accum::Replace
    } else {
        scale_tri(cm.rb_mut(), upper, beta);
        Accum::Add
    };
    let dst = if upper {
        BlockStructure::TriangularUpper
    } else {
        BlockStructure::TriangularLower
    };
    let rect = BlockStructure::Rectangular;
    triangular::matmul(
        cm.rb_mut(),
        dst,
        accum,
        opa,
        rect,
        opb.transpose(),
        rect,
        alpha,
        Par::Seq,
    );
    triangular::matmul(
        cm,
        dst,
        Accum::Add,
        opb,
        rect,
        opa.transpose(),
        rect,
        alpha,
        Par::Seq,
    );
}
