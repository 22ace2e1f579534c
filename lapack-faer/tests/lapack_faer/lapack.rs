//! LAPACK drivers (double precision) against references: Jacobi eigenvalues, reconstruction identities,
//! orthogonality, residuals; plus workspace queries, every job/range/uplo variant and the info codes.

use crate::common;
use common::*;
use lapack_faer::*;

/// Run `dsyevr_` with a workspace query first (as clarabel does) and return (info, m, w, z).
#[allow(clippy::too_many_arguments)]
fn syevr(
    jobz: u8,
    range: u8,
    uplo: u8,
    a: &[f64],
    n: usize,
    lda: usize,
    vl: f64,
    vu: f64,
    il: i32,
    iu: i32,
) -> (i32, usize, Vec<f64>, Vec<f64>, Vec<i32>) {
    let mut a = a.to_vec();
    let ni = n as i32;
    let ldai = lda as i32;
    let ldz = n.max(1) as i32;
    let mut m = -1i32;
    let mut w = vec![0.0; n];
    let mut z = vec![PAD; n * n.max(1)];
    let mut isuppz = vec![0i32; 2 * n.max(1)];
    let mut work = vec![0.0; 1];
    let mut iwork = vec![0i32; 1];
    let mut info = 99i32;
    let q = -1i32;
    unsafe {
        dsyevr_(
            &ch(jobz),
            &ch(range),
            &ch(uplo),
            &ni,
            a.as_mut_ptr(),
            &ldai,
            &vl,
            &vu,
            &il,
            &iu,
            &-1.0,
            &mut m,
            w.as_mut_ptr(),
            z.as_mut_ptr(),
            &ldz,
            isuppz.as_mut_ptr(),
            work.as_mut_ptr(),
            &q,
            iwork.as_mut_ptr(),
            &q,
            &mut info,
        )
    };
    assert_eq!(info, 0, "workspace query failed");
    let lwork = work[0] as i32;
    let liwork = iwork[0];
    assert_eq!(lwork, (26 * n as i32).max(1), "optimal lwork");
    assert_eq!(liwork, (10 * n as i32).max(1), "optimal liwork");
    work.resize(lwork as usize, 0.0);
    iwork.resize(liwork as usize, 0);
    unsafe {
        dsyevr_(
            &ch(jobz),
            &ch(range),
            &ch(uplo),
            &ni,
            a.as_mut_ptr(),
            &ldai,
            &vl,
            &vu,
            &il,
            &iu,
            &-1.0,
            &mut m,
            w.as_mut_ptr(),
            z.as_mut_ptr(),
            &ldz,
            isuppz.as_mut_ptr(),
            work.as_mut_ptr(),
            &lwork,
            iwork.as_mut_ptr(),
            &liwork,
            &mut info,
        )
    };
    (info, m.max(0) as usize, w, z, isuppz)
}

#[test]
fn dsyevr_matches_jacobi_in_every_variant() {
    let mut r = rng(10);
    for &n in &[1usize, 2, 4, 7, 12] {
        let lda = n + 2;
        let full = rand_sym(&mut r, n, lda);
        let reference = jacobi_eigenvalues(&full, lda, n);
        for &uplo in b"UL" {
            // Poison the triangle that must not be read.
            let mut a = full.clone();
            for j in 0..n {
                for i in 0..n {
                    if (uplo == b'U' && i > j) || (uplo == b'L' && i < j) {
                        a[i + j * lda] = f64::NAN;
                    }
                }
            }
            for &jobz in b"NV" {
                let (info, m, w, z, isuppz) = syevr(jobz, b'A', uplo, &a, n, lda, 0.0, 0.0, 0, 0);
                assert_eq!(info, 0);
                assert_eq!(m, n);
                assert!(
                    max_abs_diff(&w[..m], &reference) < 1e-12,
                    "eigenvalues {uplo}{jobz} n={n}"
                );
                if jobz == b'V' {
                    check_eigenvectors(&full, lda, n, &w[..m], &z, &isuppz);
                }
            }
            // range = 'I': the 2nd..=last-1 eigenvalues (or just the first for tiny n).
            let (il, iu) = if n >= 3 { (2, n as i32 - 1) } else { (1, 1) };
            let (info, m, w, z, isuppz) = syevr(b'V', b'I', uplo, &a, n, lda, 0.0, 0.0, il, iu);
            assert_eq!(info, 0);
            assert_eq!(m, (iu - il + 1) as usize);
            assert!(max_abs_diff(&w[..m], &reference[il as usize - 1..iu as usize]) < 1e-12);
            check_eigenvectors(&full, lda, n, &w[..m], &z, &isuppz);
            // range = 'V': eigenvalues in (vl, vu] with bounds between reference eigenvalues.
            if n >= 2 {
                let vl = 0.5 * (reference[0] + reference[1]);
                let vu = reference[n - 1] + 1.0;
                let (info, m, w, _, _) = syevr(b'N', b'V', uplo, &a, n, lda, vl, vu, 0, 0);
                assert_eq!(info, 0);
                assert_eq!(m, n - 1);
                assert!(max_abs_diff(&w[..m], &reference[1..]) < 1e-12);
            }
        }
    }
}

/// A z = z diag(w), zᵀz = I, and isuppz brackets the nonzeros of each column.
fn check_eigenvectors(a: &[f64], lda: usize, n: usize, w: &[f64], z: &[f64], isuppz: &[i32]) {
    let m = w.len();
    let az = naive_mul(a, lda, z, n, n, n, m);
    for k in 0..m {
        for i in 0..n {
            assert!(
                (az[i + k * n] - w[k] * z[i + k * n]).abs() < 1e-11,
                "A z != lambda z"
            );
        }
        for l in 0..m {
            let d: f64 = (0..n).map(|i| z[i + k * n] * z[i + l * n]).sum();
            assert!(
                (d - if k == l { 1.0 } else { 0.0 }).abs() < 1e-12,
                "Z not orthonormal"
            );
        }
        let (first, last) = (isuppz[2 * k] as usize, isuppz[2 * k + 1] as usize);
        assert!(first >= 1 && first <= last && last <= n);
        for i in 0..n {
            if i + 1 < first || i + 1 > last {
                assert_eq!(z[i + k * n], 0.0, "isuppz excludes a nonzero");
            }
        }
        assert_ne!(z[first - 1 + k * n], 0.0);
        assert_ne!(z[last - 1 + k * n], 0.0);
    }
}

#[test]
fn dsyevr_support_of_a_block_diagonal_matrix() {
    // diag(2, [[1, 1],[1, 1]]) ⊕ 5: eigenvectors have known supports.
    let n = 4usize;
    #[rustfmt::skip]
    let a = vec![
        2.0, 0.0, 0.0, 0.0,
        0.0, 1.0, 1.0, 0.0,
        0.0, 1.0, 1.0, 0.0,
        0.0, 0.0, 0.0, 5.0,
    ];
    let (info, m, w, _z, isuppz) = syevr(b'V', b'A', b'U', &a, n, n, 0.0, 0.0, 0, 0);
    assert_eq!((info, m), (0, 4));
    assert!(max_abs_diff(&w, &[0.0, 2.0, 2.0, 5.0]) < 1e-12);
    // The eigenvalue 5 belongs to e4 only.
    assert_eq!(&isuppz[6..8], &[4, 4]);
    // The eigenvalue 0 belongs to (e2 - e3)/√2.
    assert_eq!(&isuppz[0..2], &[2, 3]);
}

#[test]
fn dsyevr_argument_errors() {
    let n = 4i32;
    let mut a = vec![1.0; 16];
    let mut w = vec![0.0; 4];
    let mut z = vec![0.0; 16];
    let mut isuppz = vec![0i32; 8];
    let mut work = vec![0.0; 200];
    let mut iwork = vec![0i32; 40];
    let mut m = 0;
    let mut info = 0;
    let call = |jobz: u8,
                range: u8,
                lda: i32,
                ldz: i32,
                vl: f64,
                vu: f64,
                il: i32,
                iu: i32,
                lwork: i32,
                liwork: i32,
                a: &mut [f64],
                w: &mut [f64],
                z: &mut [f64],
                isuppz: &mut [i32],
                work: &mut [f64],
                iwork: &mut [i32],
                m: &mut i32,
                info: &mut i32| unsafe {
        dsyevr_(
            &ch(jobz),
            &ch(range),
            &ch(b'U'),
            &n,
            a.as_mut_ptr(),
            &lda,
            &vl,
            &vu,
            &il,
            &iu,
            &0.0,
            m,
            w.as_mut_ptr(),
            z.as_mut_ptr(),
            &ldz,
            isuppz.as_mut_ptr(),
            work.as_mut_ptr(),
            &lwork,
            iwork.as_mut_ptr(),
            &liwork,
            info,
        )
    };
    let cases: [(u8, u8, i32, i32, f64, f64, i32, i32, i32, i32, i32); 8] = [
        (b'X', b'A', 4, 4, 0.0, 0.0, 0, 0, 104, 40, -1),
        (b'V', b'Q', 4, 4, 0.0, 0.0, 0, 0, 104, 40, -2),
        (b'V', b'A', 3, 4, 0.0, 0.0, 0, 0, 104, 40, -6),
        (b'V', b'V', 4, 4, 1.0, 1.0, 0, 0, 104, 40, -8),
        (b'V', b'I', 4, 4, 0.0, 0.0, 0, 2, 104, 40, -9),
        (b'V', b'I', 4, 4, 0.0, 0.0, 2, 5, 104, 40, -10),
        (b'V', b'A', 4, 3, 0.0, 0.0, 0, 0, 104, 40, -15),
        (b'V', b'A', 4, 4, 0.0, 0.0, 0, 0, 103, 40, -18),
    ];
    for (jobz, range, lda, ldz, vl, vu, il, iu, lwork, liwork, want) in cases {
        call(
            jobz,
            range,
            lda,
            ldz,
            vl,
            vu,
            il,
            iu,
            lwork,
            liwork,
            &mut a,
            &mut w,
            &mut z,
            &mut isuppz,
            &mut work,
            &mut iwork,
            &mut m,
            &mut info,
        );
        assert_eq!(info, want, "jobz={} range={}", jobz as char, range as char);
    }
    call(
        b'V',
        b'A',
        4,
        4,
        0.0,
        0.0,
        0,
        0,
        104,
        39,
        &mut a,
        &mut w,
        &mut z,
        &mut isuppz,
        &mut work,
        &mut iwork,
        &mut m,
        &mut info,
    );
    assert_eq!(info, -20);
    // Non-finite input is reported, not iterated on.
    a[5] = f64::NAN;
    call(
        b'N',
        b'A',
        4,
        4,
        0.0,
        0.0,
        0,
        0,
        104,
        40,
        &mut a,
        &mut w,
        &mut z,
        &mut isuppz,
        &mut work,
        &mut iwork,
        &mut m,
        &mut info,
    );
    assert!(info > 0);
}

#[test]
fn dpotrf_dpotrs_both_triangles() {
    let mut r = rng(11);
    for &n in &[1usize, 3, 6, 11] {
        for &uplo in b"UL" {
            let lda = n + 1;
            let a = rand_spd(&mut r, n, lda);
            let mut f = a.clone();
            // The other triangle is not read and must stay as it was.
            for j in 0..n {
                for i in 0..n {
                    if (uplo == b'U' && i > j) || (uplo == b'L' && i < j) {
                        f[i + j * lda] = -123.0;
                    }
                }
            }
            let (ni, ldai) = (n as i32, lda as i32);
            let mut info = 9;
            unsafe { dpotrf_(&ch(uplo), &ni, f.as_mut_ptr(), &ldai, &mut info) };
            assert_eq!(info, 0);
            // Reconstruct: L Lᵀ or Uᵀ U.
            for j in 0..n {
                for i in 0..n {
                    let s: f64 = (0..n)
                        .map(|k| {
                            let (x, y) = if uplo == b'L' {
                                (
                                    if i >= k { f[i + k * lda] } else { 0.0 },
                                    if j >= k { f[j + k * lda] } else { 0.0 },
                                )
                            } else {
                                (
                                    if k <= i { f[k + i * lda] } else { 0.0 },
                                    if k <= j { f[k + j * lda] } else { 0.0 },
                                )
                            };
                            x * y
                        })
                        .sum();
                    assert!(
                        (s - a[i + j * lda]).abs() < 1e-11,
                        "factor does not reconstruct A"
                    );
                    if (uplo == b'U' && i > j) || (uplo == b'L' && i < j) {
                        assert_eq!(f[i + j * lda], -123.0, "other triangle touched");
                    }
                }
            }
            // Solve A X = B for 3 right-hand sides with a padded B.
            let nrhs = 3usize;
            let ldb = n + 2;
            let x_true = rand_mat(&mut r, n, nrhs, ldb);
            let mut b = vec![PAD; ldb * nrhs];
            let ax = naive_mul(&a, lda, &x_true, ldb, n, n, nrhs);
            for j in 0..nrhs {
                for i in 0..n {
                    b[i + j * ldb] = ax[i + j * n];
                }
            }
            let (nr, ldbi) = (nrhs as i32, ldb as i32);
            unsafe {
                dpotrs_(
                    &ch(uplo),
                    &ni,
                    &nr,
                    f.as_ptr(),
                    &ldai,
                    b.as_mut_ptr(),
                    &ldbi,
                    &mut info,
                )
            };
            assert_eq!(info, 0);
            for j in 0..nrhs {
                for i in 0..n {
                    assert!((b[i + j * ldb] - x_true[i + j * ldb]).abs() < 1e-10);
                }
                assert_eq!(b[n + j * ldb], PAD);
            }
        }
    }
}

#[test]
fn dpotrf_reports_the_failing_leading_minor() {
    // Leading minors: 4 > 0, 4·5 − 4 > 0, then the third fails (det < 0).
    #[rustfmt::skip]
    let mut a = vec![
        4.0, 2.0, 1.0, 0.0,
        2.0, 5.0, 3.0, 0.0,
        1.0, 3.0, -9.0, 0.0,
        0.0, 0.0, 0.0, 1.0,
    ];
    let a0 = a.clone();
    let (n, mut info) = (4i32, 0i32);
    unsafe { dpotrf_(&ch(b'L'), &n, a.as_mut_ptr(), &n, &mut info) };
    assert_eq!(info, 3);
    assert_eq!(a, a0, "A left unchanged on failure");
    unsafe { dpotrf_(&ch(b'Z'), &n, a.as_mut_ptr(), &n, &mut info) };
    assert_eq!(info, -1);
    let three = 3;
    unsafe { dpotrf_(&ch(b'U'), &n, a.as_mut_ptr(), &three, &mut info) };
    assert_eq!(info, -4);
    a[0] = f64::NAN;
    unsafe { dpotrf_(&ch(b'U'), &n, a.as_mut_ptr(), &n, &mut info) };
    assert_eq!(info, 1);
}

#[test]
fn dgesv_solves_and_reports_pivots() {
    let mut r = rng(12);
    for &n in &[1usize, 2, 5, 10] {
        let (lda, ldb, nrhs) = (n + 1, n + 3, 2usize);
        let a = rand_mat(&mut r, n, n, lda);
        let x_true = rand_mat(&mut r, n, nrhs, ldb);
        let ax = naive_mul(&a, lda, &x_true, ldb, n, n, nrhs);
        let mut b = vec![PAD; ldb * nrhs];
        for j in 0..nrhs {
            for i in 0..n {
                b[i + j * ldb] = ax[i + j * n];
            }
        }
        let mut f = a.clone();
        let mut ipiv = vec![0i32; n];
        let (ni, nr, ldai, ldbi) = (n as i32, nrhs as i32, lda as i32, ldb as i32);
        let mut info = 9;
        unsafe {
            dgesv_(
                &ni,
                &nr,
                f.as_mut_ptr(),
                &ldai,
                ipiv.as_mut_ptr(),
                b.as_mut_ptr(),
                &ldbi,
                &mut info,
            )
        };
        assert_eq!(info, 0);
        for j in 0..nrhs {
            for i in 0..n {
                assert!((b[i + j * ldb] - x_true[i + j * ldb]).abs() < 1e-9);
            }
        }
        // Apply the interchanges to A in LAPACK's order and compare with L U.
        let mut pa = a.clone();
        for (i, &p) in ipiv.iter().enumerate() {
            let p = p as usize - 1;
            assert!(p >= i && p < n, "ipiv out of range");
            for c in 0..n {
                pa.swap(i + c * lda, p + c * lda);
            }
        }
        for j in 0..n {
            for i in 0..n {
                let s: f64 = (0..=i.min(j))
                    .map(|k| (if k == i { 1.0 } else { f[i + k * lda] }) * f[k + j * lda])
                    .sum();
                assert!((s - pa[i + j * lda]).abs() < 1e-12, "P A != L U");
            }
            // Partial pivoting bounds the multipliers by 1.
            for i in j + 1..n {
                assert!(f[i + j * lda].abs() <= 1.0 + 1e-15);
            }
        }
    }
}

#[test]
fn dgesv_singular_matrix() {
    // Second column is twice the first: U(2,2) = 0 exactly.
    let mut a = vec![1.0, 2.0, 2.0, 4.0];
    let mut b = vec![1.0, 1.0];
    let b0 = b.clone();
    let mut ipiv = vec![0i32; 2];
    let (n, one, mut info) = (2i32, 1i32, 0i32);
    unsafe {
        dgesv_(
            &n,
            &one,
            a.as_mut_ptr(),
            &n,
            ipiv.as_mut_ptr(),
            b.as_mut_ptr(),
            &n,
            &mut info,
        )
    };
    assert_eq!(info, 2);
    assert_eq!(b, b0, "no solution computed for a singular matrix");
    let neg = -1;
    unsafe {
        dgesv_(
            &neg,
            &one,
            a.as_mut_ptr(),
            &n,
            ipiv.as_mut_ptr(),
            b.as_mut_ptr(),
            &n,
            &mut info,
        )
    };
    assert_eq!(info, -1);
}

/// Check `A = U diag(s) Vᵀ` (on the first k columns/rows), orthonormal columns of U and rows of Vᵀ, and
/// s descending, non-negative and equal to the square roots of the Jacobi eigenvalues of AᵀA.
#[allow(clippy::too_many_arguments)]
fn check_svd(
    a: &[f64],
    lda: usize,
    m: usize,
    n: usize,
    s: &[f64],
    u: Option<(&[f64], usize, usize)>,
    vt: Option<(&[f64], usize, usize)>,
) {
    let k = m.min(n);
    let ata = naive_mul(&transpose(a, lda, m, n), n, a, lda, n, m, n);
    let mut ev = jacobi_eigenvalues(&ata, n, n);
    ev.reverse();
    for i in 0..k {
        assert!(s[i] >= 0.0);
        if i > 0 {
            assert!(s[i] <= s[i - 1], "singular values not descending");
        }
        assert!(
            (s[i] - ev[i].max(0.0).sqrt()).abs() < 1e-10,
            "singular value {i}"
        );
    }
    if let Some((u, ldu, ucols)) = u {
        for p in 0..ucols {
            for q in 0..ucols {
                let d: f64 = (0..m).map(|i| u[i + p * ldu] * u[i + q * ldu]).sum();
                assert!(
                    (d - if p == q { 1.0 } else { 0.0 }).abs() < 1e-11,
                    "U not orthonormal"
                );
            }
        }
        if let Some((vt, ldvt, vrows)) = vt {
            for q in 0..vrows {
                for p in 0..vrows {
                    let d: f64 = (0..n).map(|j| vt[q + j * ldvt] * vt[p + j * ldvt]).sum();
                    assert!(
                        (d - if p == q { 1.0 } else { 0.0 }).abs() < 1e-11,
                        "Vt rows not orthonormal"
                    );
                }
            }
            for j in 0..n {
                for i in 0..m {
                    let r: f64 = (0..k)
                        .map(|l| u[i + l * ldu] * s[l] * vt[l + j * ldvt])
                        .sum();
                    assert!((r - a[i + j * lda]).abs() < 1e-11, "U S Vt != A");
                }
            }
        }
    }
}

fn transpose(a: &[f64], lda: usize, m: usize, n: usize) -> Vec<f64> {
    let mut t = vec![0.0; n * m];
    for j in 0..n {
        for i in 0..m {
            t[j + i * n] = a[i + j * lda];
        }
    }
    t
}

#[test]
fn dgesdd_every_job_and_shape() {
    let mut r = rng(13);
    for &(m, n) in &[(5usize, 5usize), (7, 4), (3, 6), (1, 4), (4, 1)] {
        let k = m.min(n);
        let lda = m + 1;
        let a = rand_mat(&mut r, m, n, lda);
        for &job in b"ASON" {
            let (ucols, vrows) = match job {
                b'A' => (m, n),
                _ => (k, k),
            };
            let ldu = m + 2;
            let ldvt = if job == b'A' || (job == b'O' && m >= n) {
                n + 1
            } else {
                k + 1
            };
            let mut f = a.clone();
            let mut s = vec![0.0; k];
            let mut u = vec![PAD; ldu * m];
            let mut vt = vec![PAD; ldvt * n];
            let mut iwork = vec![0i32; 8 * k];
            let mut work = vec![0.0; 1];
            let (mi, ni, ldai, ldui, ldvti) =
                (m as i32, n as i32, lda as i32, ldu as i32, ldvt as i32);
            let mut info = 9;
            unsafe {
                dgesdd_(
                    &ch(job),
                    &mi,
                    &ni,
                    f.as_mut_ptr(),
                    &ldai,
                    s.as_mut_ptr(),
                    u.as_mut_ptr(),
                    &ldui,
                    vt.as_mut_ptr(),
                    &ldvti,
                    work.as_mut_ptr(),
                    &-1,
                    iwork.as_mut_ptr(),
                    &mut info,
                )
            };
            assert_eq!(info, 0);
            let lwork = work[0] as i32;
            assert!(lwork >= 1);
            work.resize(lwork as usize, 0.0);
            // One less than the documented minimum is refused.
            unsafe {
                dgesdd_(
                    &ch(job),
                    &mi,
                    &ni,
                    f.as_mut_ptr(),
                    &ldai,
                    s.as_mut_ptr(),
                    u.as_mut_ptr(),
                    &ldui,
                    vt.as_mut_ptr(),
                    &ldvti,
                    work.as_mut_ptr(),
                    &(lwork - 1),
                    iwork.as_mut_ptr(),
                    &mut info,
                )
            };
            assert_eq!(info, -12);
            unsafe {
                dgesdd_(
                    &ch(job),
                    &mi,
                    &ni,
                    f.as_mut_ptr(),
                    &ldai,
                    s.as_mut_ptr(),
                    u.as_mut_ptr(),
                    &ldui,
                    vt.as_mut_ptr(),
                    &ldvti,
                    work.as_mut_ptr(),
                    &lwork,
                    iwork.as_mut_ptr(),
                    &mut info,
                )
            };
            assert_eq!(info, 0);
            match job {
                b'N' => check_svd(&a, lda, m, n, &s, None, None),
                b'O' if m >= n => {
                    check_svd(&a, lda, m, n, &s, Some((&f, lda, k)), Some((&vt, ldvt, n)))
                }
                b'O' => check_svd(&a, lda, m, n, &s, Some((&u, ldu, m)), Some((&f, lda, k))),
                _ => check_svd(
                    &a,
                    lda,
                    m,
                    n,
                    &s,
                    Some((&u, ldu, ucols)),
                    Some((&vt, ldvt, vrows)),
                ),
            }
        }
    }
}

#[test]
fn dgesvd_every_job_pair() {
    let mut r = rng(14);
    for &(m, n) in &[(6usize, 6usize), (8, 3), (3, 8)] {
        let k = m.min(n);
        let lda = m + 2;
        let a = rand_mat(&mut r, m, n, lda);
        for &ju in b"ASON" {
            for &jv in b"ASON" {
                let mut f = a.clone();
                let mut s = vec![0.0; k];
                let ldu = m + 1;
                let ldvt = n + 1;
                let mut u = vec![PAD; ldu * m];
                let mut vt = vec![PAD; ldvt * n];
                let mut work = vec![0.0; 1];
                let (mi, ni, ldai, ldui, ldvti) =
                    (m as i32, n as i32, lda as i32, ldu as i32, ldvt as i32);
                let mut info = 9;
                unsafe {
                    dgesvd_(
                        &ch(ju),
                        &ch(jv),
                        &mi,
                        &ni,
                        f.as_mut_ptr(),
                        &ldai,
                        s.as_mut_ptr(),
                        u.as_mut_ptr(),
                        &ldui,
                        vt.as_mut_ptr(),
                        &ldvti,
                        work.as_mut_ptr(),
                        &-1,
                        &mut info,
                    )
                };
                if ju == b'O' && jv == b'O' {
                    assert_eq!(info, -2);
                    continue;
                }
                assert_eq!(info, 0);
                let lwork = work[0] as i32;
                assert_eq!(lwork, (3 * k + m.max(n)).max(5 * k) as i32);
                work.resize(lwork as usize, 0.0);
                unsafe {
                    dgesvd_(
                        &ch(ju),
                        &ch(jv),
                        &mi,
                        &ni,
                        f.as_mut_ptr(),
                        &ldai,
                        s.as_mut_ptr(),
                        u.as_mut_ptr(),
                        &ldui,
                        vt.as_mut_ptr(),
                        &ldvti,
                        work.as_mut_ptr(),
                        &lwork,
                        &mut info,
                    )
                };
                assert_eq!(info, 0);
                let uu: Option<(&[f64], usize, usize)> = match ju {
                    b'A' => Some((&u, ldu, m)),
                    b'S' => Some((&u, ldu, k)),
                    b'O' => Some((&f, lda, k)),
                    _ => None,
                };
                let vv: Option<(&[f64], usize, usize)> = match jv {
                    b'A' => Some((&vt, ldvt, n)),
                    b'S' => Some((&vt, ldvt, k)),
                    b'O' => Some((&f, lda, k)),
                    _ => None,
                };
                check_svd(&a, lda, m, n, &s, uu, vv);
                // Vt alone still has orthonormal rows.
                if uu.is_none() {
                    if let Some((vt, ldvt, rows)) = vv {
                        for p in 0..rows {
                            let d: f64 = (0..n).map(|j| vt[p + j * ldvt].powi(2)).sum();
                            assert!((d - 1.0).abs() < 1e-11);
                        }
                    }
                }
            }
        }
    }
}
