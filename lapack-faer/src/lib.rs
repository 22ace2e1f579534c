//! Fortran-ABI BLAS/LAPACK symbols (`dsyevr_`, `dpotrf_`, ...) implemented with faer, so that clarabel's `sdp`
//! feature links without a system BLAS/LAPACK.
//!
//! The set is exactly what clarabel 0.11 instantiates (its `algebra/dense/blas/traits.rs`), in both
//! precisions: `?syevr ?potrf ?potrs ?gesdd ?gesvd ?gemm ?gemv ?symv ?syrk ?syr2k ?gesv` with `? ∈ {d, s}`.
//! Signatures are those `lapack-sys` 0.14 / `blas-sys` 0.7 declare: every argument by pointer, characters as
//! `c_char`, integers as `i32`, and no hidden string-length arguments.
//!
//! A crate that only needs the symbols at link time should mention this crate (`use lapack_faer as _;`) so
//! that rustc passes it to the linker.
//!
//! Why by hand: no maintained crate provides LAPACK's Fortran ABI on top of a pure-Rust backend, and the
//! project forbids a system BLAS/LAPACK; faer does all the numerical work, this crate only adapts conventions.

mod blas;
mod lapack;
mod scalar;

use core::ffi::c_char;

/// Generates one `#[no_mangle] extern "C"` symbol per precision for each routine. Inside the generated
/// modules `T` names the precision, so the argument lists below are written once for both.
macro_rules! fortran_symbols {
    ($( $d:ident, $s:ident => $module:ident :: $f:ident { $($arg:ident : $ty:ty),* $(,)? } )*) => {
        /// Double-precision symbols.
        mod double {
            #[allow(unused_imports)]
            use super::*;
            #[allow(dead_code)]
            type T = f64;
            $(
                #[doc = concat!("Fortran-ABI `", stringify!($d), "`; see the crate docs.\n\n# Safety\nFortran calling convention: every pointer valid for the sizes the arguments describe.")]
                #[no_mangle]
                #[allow(clippy::too_many_arguments)]
                pub unsafe extern "C" fn $d($($arg: $ty),*) {
                    unsafe { crate::$module::$f::<T>(stringify!($d), $($arg),*) }
                }
            )*
        }
        /// Single-precision symbols.
        mod single {
            #[allow(unused_imports)]
            use super::*;
            #[allow(dead_code)]
            type T = f32;
            $(
                #[doc = concat!("Fortran-ABI `", stringify!($s), "`; see the crate docs.\n\n# Safety\nFortran calling convention: every pointer valid for the sizes the arguments describe.")]
                #[no_mangle]
                #[allow(clippy::too_many_arguments)]
                pub unsafe extern "C" fn $s($($arg: $ty),*) {
                    unsafe { crate::$module::$f::<T>(stringify!($s), $($arg),*) }
                }
            )*
        }
        pub use double::{$($d),*};
        pub use single::{$($s),*};
    };
}

fortran_symbols! {
    dgemm_, sgemm_ => blas::gemm {
        transa: *const c_char, transb: *const c_char, m: *const i32, n: *const i32, k: *const i32,
        alpha: *const T, a: *const T, lda: *const i32, b: *const T, ldb: *const i32, beta: *const T,
        c: *mut T, ldc: *const i32,
    }
    dgemv_, sgemv_ => blas::gemv {
        trans: *const c_char, m: *const i32, n: *const i32, alpha: *const T, a: *const T, lda: *const i32,
        x: *const T, incx: *const i32, beta: *const T, y: *mut T, incy: *const i32,
    }
    dsymv_, ssymv_ => blas::symv {
        uplo: *const c_char, n: *const i32, alpha: *const T, a: *const T, lda: *const i32, x: *const T,
        incx: *const i32, beta: *const T, y: *mut T, incy: *const i32,
    }
    dsyrk_, ssyrk_ => blas::syrk {
        uplo: *const c_char, trans: *const c_char, n: *const i32, k: *const i32, alpha: *const T,
        a: *const T, lda: *const i32, beta: *const T, c: *mut T, ldc: *const i32,
    }
    dsyr2k_, ssyr2k_ => blas::syr2k {
        uplo: *const c_char, trans: *const c_char, n: *const i32, k: *const i32, alpha: *const T,
        a: *const T, lda: *const i32, b: *const T, ldb: *const i32, beta: *const T, c: *mut T,
        ldc: *const i32,
    }
    dsyevr_, ssyevr_ => lapack::syevr {
        jobz: *const c_char, range: *const c_char, uplo: *const c_char, n: *const i32, a: *mut T,
        lda: *const i32, vl: *const T, vu: *const T, il: *const i32, iu: *const i32, abstol: *const T,
        m: *mut i32, w: *mut T, z: *mut T, ldz: *const i32, isuppz: *mut i32, work: *mut T,
        lwork: *const i32, iwork: *mut i32, liwork: *const i32, info: *mut i32,
    }
    dpotrf_, spotrf_ => lapack::potrf {
        uplo: *const c_char, n: *const i32, a: *mut T, lda: *const i32, info: *mut i32,
    }
    dpotrs_, spotrs_ => lapack::potrs {
        uplo: *const c_char, n: *const i32, nrhs: *const i32, a: *const T, lda: *const i32, b: *mut T,
        ldb: *const i32, info: *mut i32,
    }
    dgesv_, sgesv_ => lapack::gesv {
        n: *const i32, nrhs: *const i32, a: *mut T, lda: *const i32, ipiv: *mut i32, b: *mut T,
        ldb: *const i32, info: *mut i32,
    }
    dgesdd_, sgesdd_ => lapack::gesdd {
        jobz: *const c_char, m: *const i32, n: *const i32, a: *mut T, lda: *const i32, s: *mut T,
        u: *mut T, ldu: *const i32, vt: *mut T, ldvt: *const i32, work: *mut T, lwork: *const i32,
        iwork: *mut i32, info: *mut i32,
    }
    dgesvd_, sgesvd_ => lapack::gesvd {
        jobu: *const c_char, jobvt: *const c_char, m: *const i32, n: *const i32, a: *mut T,
        lda: *const i32, s: *mut T, u: *mut T, ldu: *const i32, vt: *mut T, ldvt: *const i32,
        work: *mut T, lwork: *const i32, info: *mut i32,
    }
}
