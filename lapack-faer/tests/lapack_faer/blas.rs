//! BLAS routines (double precision) against triple-loop references: every trans/uplo variant, padded
//! leading dimensions, negative increments, the `beta = 0` / `alpha = 0` conventions, untouched storage.

use crate::common;
use common::*;
use lapack_faer::*;

const TOL: f64 = 1e-12;

#[test]
fn dgemm_all_transposes_with_padding_and_beta() {
    let mut r = rng(1);
    for &(m, n, k) in &[(3usize, 4usize, 5usize), (7, 2, 1), (1, 1, 6), (9, 8, 7)] {
        for &ta in b"NTC" {
            for &tb in b"NTtn" {
                for &(alpha, beta) in &[(1.0, 0.0), (-0.7, 1.0), (2.5, -0.3)] {
                    let (ar, ac) = if ta == b'N' { (m, k) } else { (k, m) };
                    let (br, bc) = if tb.to_ascii_uppercase() == b'N' {
                        (k, n)
                    } else {
                        (n, k)
                    };
                    let (lda, ldb, ldc) = (ar + 2, br + 1, m + 3);
                    let a = rand_mat(&mut r, ar, ac, lda);
                    let b = rand_mat(&mut r, br, bc, ldb);
                    let mut c = rand_mat(&mut r, m, n, ldc);
                    if beta == 0.0 {
                        // beta = 0 means C is not read: NaNs in it must not propagate.
                        for j in 0..n {
                            for i in 0..m {
                                c[i + j * ldc] = f64::NAN;
                            }
                        }
                    }
                    let c0 = c.clone();
                    let (mi, ni, ki, ldai, ldbi, ldci) = (
                        m as i32, n as i32, k as i32, lda as i32, ldb as i32, ldc as i32,
                    );
                    unsafe {
                        dgemm_(
                            &ch(ta),
                            &ch(tb),
                            &mi,
                            &ni,
                            &ki,
                            &alpha,
                            a.as_ptr(),
                            &ldai,
                            b.as_ptr(),
                            &ldbi,
                            &beta,
                            c.as_mut_ptr(),
                            &ldci,
                        );
                    }
                    let tbt = tb.to_ascii_uppercase() != b'N';
                    for j in 0..n {
                        for i in 0..m {
                            let mut s = 0.0;
                            for l in 0..k {
                                s += op_at(&a, lda, ta != b'N', i, l) * op_at(&b, ldb, tbt, l, j);
                            }
                            let prev = if beta == 0.0 {
                                0.0
                            } else {
                                beta * c0[i + j * ldc]
                            };
                            let want = alpha * s + prev;
                            assert!(
                                (c[i + j * ldc] - want).abs() < TOL,
                                "gemm {ta} {tb} ({i},{j})"
                            );
                        }
                        for i in m..ldc {
                            assert_eq!(c[i + j * ldc], PAD, "padding of C written");
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn dgemm_alpha_zero_does_not_read_a_and_b() {
    let (m, n, k) = (3i32, 2i32, 4i32);
    let a = vec![f64::NAN; 12];
    let b = vec![f64::NAN; 8];
    let mut c = vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    unsafe {
        dgemm_(
            &ch(b'N'),
            &ch(b'N'),
            &m,
            &n,
            &k,
            &0.0,
            a.as_ptr(),
            &m,
            b.as_ptr(),
            &k,
            &2.0,
            c.as_mut_ptr(),
            &m,
        )
    };
    assert_eq!(c, vec![2.0, 4.0, 6.0, 8.0, 10.0, 12.0]);
    let mut c = vec![f64::NAN; 6];
    unsafe {
        dgemm_(
            &ch(b'N'),
            &ch(b'N'),
            &m,
            &n,
            &k,
            &0.0,
            a.as_ptr(),
            &m,
            b.as_ptr(),
            &k,
            &0.0,
            c.as_mut_ptr(),
            &m,
        )
    };
    assert_eq!(c, vec![0.0; 6]);
}

#[test]
fn dgemm_illegal_argument_leaves_c_alone() {
    let a = [1.0; 4];
    let mut c = [3.0; 4];
    let (two, one) = (2i32, 1i32);
    // ldc = 1 < m = 2 is argument 13: reported, nothing computed.
    unsafe {
        dgemm_(
            &ch(b'N'),
            &ch(b'N'),
            &two,
            &two,
            &two,
            &1.0,
            a.as_ptr(),
            &two,
            a.as_ptr(),
            &two,
            &0.0,
            c.as_mut_ptr(),
            &one,
        )
    };
    assert_eq!(c, [3.0; 4]);
    // An invalid trans flag is argument 1.
    unsafe {
        dgemm_(
            &ch(b'X'),
            &ch(b'N'),
            &two,
            &two,
            &two,
            &1.0,
            a.as_ptr(),
            &two,
            a.as_ptr(),
            &two,
            &0.0,
            c.as_mut_ptr(),
            &two,
        )
    };
    assert_eq!(c, [3.0; 4]);
}

/// Element `i` of a BLAS vector of length `n` with increment `inc`.
fn vidx(i: usize, n: usize, inc: i32) -> usize {
    if inc > 0 {
        i * inc as usize
    } else {
        (n - 1 - i) * inc.unsigned_abs() as usize
    }
}

#[test]
fn dgemv_trans_and_increments() {
    let mut r = rng(2);
    for &(m, n) in &[(4usize, 3usize), (1, 5), (6, 6)] {
        for &t in b"NT" {
            for &(incx, incy) in &[(1i32, 1i32), (2, -1), (-3, 2)] {
                for &(alpha, beta) in &[(1.3, 0.0), (0.5, -2.0)] {
                    let lda = m + 1;
                    let a = rand_mat(&mut r, m, n, lda);
                    let (lx, ly) = if t == b'N' { (n, m) } else { (m, n) };
                    let x = rand_mat(
                        &mut r,
                        1 + (lx - 1) * incx.unsigned_abs() as usize,
                        1,
                        1 + (lx - 1) * incx.unsigned_abs() as usize,
                    );
                    let sy = 1 + (ly - 1) * incy.unsigned_abs() as usize;
                    let mut y = rand_mat(&mut r, sy, 1, sy);
                    if beta == 0.0 {
                        for i in 0..ly {
                            y[vidx(i, ly, incy)] = f64::NAN;
                        }
                    }
                    let y0 = y.clone();
                    let (mi, ni, ldai) = (m as i32, n as i32, lda as i32);
                    unsafe {
                        dgemv_(
                            &ch(t),
                            &mi,
                            &ni,
                            &alpha,
                            a.as_ptr(),
                            &ldai,
                            x.as_ptr(),
                            &incx,
                            &beta,
                            y.as_mut_ptr(),
                            &incy,
                        )
                    };
                    for i in 0..ly {
                        let mut s = 0.0;
                        for l in 0..lx {
                            s += op_at(&a, lda, t == b'T', i, l) * x[vidx(l, lx, incx)];
                        }
                        let prev = if beta == 0.0 {
                            0.0
                        } else {
                            beta * y0[vidx(i, ly, incy)]
                        };
                        assert!(
                            (y[vidx(i, ly, incy)] - (alpha * s + prev)).abs() < TOL,
                            "gemv {t} inc {incx},{incy}"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn dsymv_reads_only_its_triangle() {
    let mut r = rng(3);
    for &n in &[1usize, 4, 9] {
        for &u in b"ULul" {
            for &(incx, incy) in &[(1i32, 1i32), (-2, 3)] {
                let lda = n + 2;
                let full = rand_sym(&mut r, n, lda);
                let mut a = full.clone();
                // Poison the triangle that must not be read.
                for j in 0..n {
                    for i in 0..n {
                        let unused = if u.to_ascii_uppercase() == b'U' {
                            i > j
                        } else {
                            i < j
                        };
                        if unused {
                            a[i + j * lda] = f64::NAN;
                        }
                    }
                }
                let sx = 1 + (n - 1) * incx.unsigned_abs() as usize;
                let sy = 1 + (n - 1) * incy.unsigned_abs() as usize;
                let x = rand_mat(&mut r, sx, 1, sx);
                let mut y = rand_mat(&mut r, sy, 1, sy);
                let y0 = y.clone();
                let (alpha, beta) = (0.8, 1.7);
                let (ni, ldai) = (n as i32, lda as i32);
                unsafe {
                    dsymv_(
                        &ch(u),
                        &ni,
                        &alpha,
                        a.as_ptr(),
                        &ldai,
                        x.as_ptr(),
                        &incx,
                        &beta,
                        y.as_mut_ptr(),
                        &incy,
                    )
                };
                for i in 0..n {
                    let s: f64 = (0..n)
                        .map(|l| at(&full, lda, i, l) * x[vidx(l, n, incx)])
                        .sum();
                    let want = alpha * s + beta * y0[vidx(i, n, incy)];
                    assert!((y[vidx(i, n, incy)] - want).abs() < TOL, "symv {u} n={n}");
                }
            }
        }
    }
}

#[test]
fn dsyrk_and_dsyr2k_touch_only_their_triangle() {
    let mut r = rng(4);
    for &(n, k) in &[(4usize, 3usize), (5, 1), (1, 4), (8, 8)] {
        for &u in b"UL" {
            for &t in b"NTC" {
                for &(alpha, beta) in &[(1.0, 0.0), (-0.5, 1.0), (1.5, 0.25)] {
                    let (ar, ac) = if t == b'N' { (n, k) } else { (k, n) };
                    let (lda, ldb, ldc) = (ar + 1, ar + 3, n + 2);
                    let a = rand_mat(&mut r, ar, ac, lda);
                    let b = rand_mat(&mut r, ar, ac, ldb);
                    let c_init = rand_mat(&mut r, n, n, ldc);
                    let in_tri = |i: usize, j: usize| if u == b'U' { i <= j } else { i >= j };
                    let (ni, ki, ldai, ldbi, ldci) =
                        (n as i32, k as i32, lda as i32, ldb as i32, ldc as i32);
                    // op(X)[i, l] with op(X) n×k.
                    let opx =
                        |x: &[f64], ld: usize, i: usize, l: usize| op_at(x, ld, t != b'N', i, l);

                    let mut c = c_init.clone();
                    if beta == 0.0 {
                        for j in 0..n {
                            for i in 0..n {
                                if in_tri(i, j) {
                                    c[i + j * ldc] = f64::NAN;
                                }
                            }
                        }
                    }
                    unsafe {
                        dsyrk_(
                            &ch(u),
                            &ch(t),
                            &ni,
                            &ki,
                            &alpha,
                            a.as_ptr(),
                            &ldai,
                            &beta,
                            c.as_mut_ptr(),
                            &ldci,
                        )
                    };
                    for j in 0..n {
                        for i in 0..ldc {
                            if i < n && in_tri(i, j) {
                                let s: f64 = (0..k)
                                    .map(|l| opx(&a, lda, i, l) * opx(&a, lda, j, l))
                                    .sum();
                                let prev = if beta == 0.0 {
                                    0.0
                                } else {
                                    beta * c_init[i + j * ldc]
                                };
                                assert!(
                                    (c[i + j * ldc] - (alpha * s + prev)).abs() < TOL,
                                    "syrk {u}{t}"
                                );
                            } else {
                                assert_eq!(
                                    c[i + j * ldc],
                                    c_init[i + j * ldc],
                                    "syrk wrote outside its triangle"
                                );
                            }
                        }
                    }

                    let mut c = c_init.clone();
                    unsafe {
                        dsyr2k_(
                            &ch(u),
                            &ch(t),
                            &ni,
                            &ki,
                            &alpha,
                            a.as_ptr(),
                            &ldai,
                            b.as_ptr(),
                            &ldbi,
                            &beta,
                            c.as_mut_ptr(),
                            &ldci,
                        )
                    };
                    for j in 0..n {
                        for i in 0..ldc {
                            if i < n && in_tri(i, j) {
                                let s: f64 = (0..k)
                                    .map(|l| {
                                        opx(&a, lda, i, l) * opx(&b, ldb, j, l)
                                            + opx(&b, ldb, i, l) * opx(&a, lda, j, l)
                                    })
                                    .sum();
                                let want = alpha * s + beta * c_init[i + j * ldc];
                                assert!((c[i + j * ldc] - want).abs() < TOL, "syr2k {u}{t}");
                            } else {
                                assert_eq!(
                                    c[i + j * ldc],
                                    c_init[i + j * ldc],
                                    "syr2k wrote outside its triangle"
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn zero_sizes_are_quick_returns() {
    let zero = 0i32;
    let one = 1i32;
    let mut c = [5.0];
    let a = [1.0];
    unsafe {
        dgemm_(
            &ch(b'N'),
            &ch(b'N'),
            &one,
            &one,
            &zero,
            &1.0,
            a.as_ptr(),
            &one,
            a.as_ptr(),
            &one,
            &1.0,
            c.as_mut_ptr(),
            &one,
        )
    };
    assert_eq!(c, [5.0]);
    // k = 0 with beta != 1 still scales C.
    unsafe {
        dgemm_(
            &ch(b'N'),
            &ch(b'N'),
            &one,
            &one,
            &zero,
            &1.0,
            a.as_ptr(),
            &one,
            a.as_ptr(),
            &one,
            &3.0,
            c.as_mut_ptr(),
            &one,
        )
    };
    assert_eq!(c, [15.0]);
    unsafe {
        dsyrk_(
            &ch(b'U'),
            &ch(b'N'),
            &zero,
            &zero,
            &1.0,
            a.as_ptr(),
            &one,
            &0.0,
            c.as_mut_ptr(),
            &one,
        )
    };
    assert_eq!(c, [15.0]);
}
