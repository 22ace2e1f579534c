//! The scalar trait the generic routines are written against (f32 and f64), and small helpers shared by the
//! BLAS and LAPACK halves: Fortran character flags, raw-pointer views into column-major storage, and the
//! `xerbla`-style diagnostic for illegal arguments.

use core::ffi::c_char;
use core::ops::{Add, Div, Mul, Neg, Sub};
use core::ptr::NonNull;
use faer::{ColMut, ColRef, MatMut, MatRef};

/// A real floating-point type with the faer traits the decompositions need.
pub(crate) trait Real:
    faer::traits::RealField
    + Copy
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + 'static
{
    const ZERO: Self;
    const ONE: Self;
    /// Sizes are reported back through `work[0]`, which LAPACK stores in the working precision.
    fn from_usize(n: usize) -> Self;
    fn finite(self) -> bool;
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    fn from_usize(n: usize) -> Self {
        n as f64
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    fn from_usize(n: usize) -> Self {
        n as f32
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
}

/// Read a Fortran CHARACTER*1 argument, upper-cased (LAPACK's `LSAME` is case-insensitive).
///
/// # Safety
/// `c` must point to a readable byte.
#[inline]
pub(crate) unsafe fn flag(c: *const c_char) -> u8 {
    if c.is_null() {
        0
    } else {
        (unsafe { *c } as u8).to_ascii_uppercase()
    }
}

/// Read a Fortran INTEGER argument passed by reference.
///
/// # Safety
/// `p` must point to a readable `i32`.
#[inline]
pub(crate) unsafe fn int(p: *const i32) -> i32 {
    unsafe { *p }
}

/// Read a scalar argument passed by reference.
///
/// # Safety
/// `p` must point to a readable `T`.
#[inline]
pub(crate) unsafe fn val<T: Copy>(p: *const T) -> T {
    unsafe { *p }
}

/// Report an illegal argument the way reference BLAS's `XERBLA` does, but without stopping the process
/// (a library must not abort its host). `info` is the 1-based position of the offending argument.
pub(crate) fn xerbla(name: &str, info: i32) {
    eprintln!(" ** On entry to {name} parameter number {info:2} had an illegal value");
}

/// `max(1, n)` as LAPACK writes it for leading-dimension checks.
#[inline]
pub(crate) fn max1(n: i32) -> i32 {
    n.max(1)
}

/// A view of an `nrows × ncols` column-major matrix with leading dimension `ld`.
///
/// # Safety
/// For a non-empty shape, `p` must point to `ld * (ncols - 1) + nrows` readable elements that stay valid and
/// unaliased by writers for `'a`.
#[inline]
pub(crate) unsafe fn mat_ref<'a, T>(
    p: *const T,
    nrows: usize,
    ncols: usize,
    ld: usize,
) -> MatRef<'a, T> {
    let p = if nrows == 0 || ncols == 0 || p.is_null() {
        NonNull::<T>::dangling().as_ptr() as *const T
    } else {
        p
    };
    unsafe { MatRef::from_raw_parts(p, nrows, ncols, 1isize, ld.max(1) as isize) }
}

/// Mutable counterpart of [`mat_ref`].
///
/// # Safety
/// As [`mat_ref`], with exclusive access for `'a`.
#[inline]
pub(crate) unsafe fn mat_mut<'a, T>(
    p: *mut T,
    nrows: usize,
    ncols: usize,
    ld: usize,
) -> MatMut<'a, T> {
    let p = if nrows == 0 || ncols == 0 || p.is_null() {
        NonNull::<T>::dangling().as_ptr()
    } else {
        p
    };
    unsafe { MatMut::from_raw_parts_mut(p, nrows, ncols, 1isize, ld.max(1) as isize) }
}

/// A BLAS vector of `n` elements with increment `inc` (negative increments walk backwards from the end of
/// the storage, as in reference BLAS).
///
/// # Safety
/// `p` must point to `1 + (n - 1) * |inc|` readable elements for `'a`; `inc != 0`.
#[inline]
pub(crate) unsafe fn vec_ref<'a, T>(p: *const T, n: usize, inc: i32) -> ColRef<'a, T> {
    if n == 0 || p.is_null() {
        return unsafe {
            ColRef::from_raw_parts(NonNull::<T>::dangling().as_ptr() as *const T, 0, 1isize)
        };
    }
    let start = if inc < 0 {
        unsafe { p.add((n - 1) * inc.unsigned_abs() as usize) }
    } else {
        p
    };
    unsafe { ColRef::from_raw_parts(start, n, inc as isize) }
}

/// Mutable counterpart of [`vec_ref`].
///
/// # Safety
/// As [`vec_ref`], with exclusive access for `'a`.
#[inline]
pub(crate) unsafe fn vec_mut<'a, T>(p: *mut T, n: usize, inc: i32) -> ColMut<'a, T> {
    if n == 0 || p.is_null() {
        return unsafe { ColMut::from_raw_parts_mut(NonNull::<T>::dangling().as_ptr(), 0, 1isize) };
    }
    let start = if inc < 0 {
        unsafe { p.add((n - 1) * inc.unsigned_abs() as usize) }
    } else {
        p
    };
    unsafe { ColMut::from_raw_parts_mut(start, n, inc as isize) }
}
