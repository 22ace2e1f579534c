//! Single-precision symbols: each `s*` routine against the f64 reference computation on the same data
//! (clarabel instantiates both precisions, so both must link and compute correctly).

use crate::common;
use common::*;
use lapack_faer::*;

const TOL: f32 = 2e-4;

fn to32(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

#[test]
fn sgemm_sgemv_ssymv_ssyrk_ssyr2k() {
    let mut r = rng(20);
    let (m, n, k) = (5usize, 4usize, 3usize);
    let a = rand_mat(&mut r, k, m, k); // used transposed: op(A) m×k
    let b = rand_mat(&mut r, k, n, k);
    let c = rand_mat(&mut r, m, n, m);
    let (mut c32, a32, b32) = (to32(&c), to32(&a), to32(&b));
    let (mi, ni, ki) = (m as i32, n as i32, k as i32);
    unsafe {
        sgemm_(
            &ch(b'T'),
            &ch(b'N'),
            &mi,
            &ni,
            &ki,
            &1.5,
            a32.as_ptr(),
            &ki,
            b32.as_ptr(),
            &ki,
            &-0.5,
            c32.as_mut_ptr(),
            &mi,
        )
    };
    let at = naive_mul(&transpose(&a, k, k, m), m, &b, k, m, k, n);
    for i in 0..m * n {
        assert!((c32[i] - (1.5 * at[i] - 0.5 * c[i]) as f32).abs() < TOL);
    }

    let x = rand_mat(&mut r, n, 1, n);
    let mut y = vec![0f32; m];
    let c32 = to32(&c);
    unsafe {
        sgemv_(
            &ch(b'N'),
            &mi,
            &ni,
            &1.0,
            c32.as_ptr(),
            &mi,
            to32(&x).as_ptr(),
            &1,
            &0.0,
            y.as_mut_ptr(),
            &1,
        )
    };
    let cx = naive_mul(&c, m, &x, n, m, n, 1);
    for i in 0..m {
        assert!((y[i] - cx[i] as f32).abs() < TOL);
    }

    let s = rand_sym(&mut r, n, n);
    let mut y = vec![0f32; n];
    unsafe {
        ssymv_(
            &ch(b'L'),
            &ni,
            &1.0,
            to32(&s).as_ptr(),
            &ni,
            to32(&x).as_ptr(),
            &1,
            &0.0,
            y.as_mut_ptr(),
            &1,
        )
    };
    let sx = naive_mul(&s, n, &x, n, n, n, 1);
    for i in 0..n {
        assert!((y[i] - sx[i] as f32).abs() < TOL);
    }

    // C (m×m, upper) = A_opᵀ-style products: op(A) = Aᵀ with A k×m.
    let mut cu = vec![0f32; m * m];
    unsafe {
        ssyrk_(
            &ch(b'U'),
            &ch(b'T'),
            &mi,
            &ki,
            &1.0,
            a32.as_ptr(),
            &ki,
            &0.0,
            cu.as_mut_ptr(),
            &mi,
        )
    };
    let ata = naive_mul(&transpose(&a, k, k, m), m, &a, k, m, k, m);
    let a2 = rand_mat(&mut r, k, m, k);
    let mut c2 = vec![0f32; m * m];
    unsafe {
        ssyr2k_(
            &ch(b'U'),
            &ch(b'T'),
            &mi,
            &ki,
            &1.0,
            a32.as_ptr(),
            &ki,
            to32(&a2).as_ptr(),
            &ki,
            &0.0,
            c2.as_mut_ptr(),
            &mi,
        )
    };
    let at_a2 = naive_mul(&transpose(&a, k, k, m), m, &a2, k, m, k, m);
    for j in 0..m {
        for i in 0..=j {
            assert!((cu[i + j * m] - ata[i + j * m] as f32).abs() < TOL);
            let want = at_a2[i + j * m] + at_a2[j + i * m];
            assert!((c2[i + j * m] - want as f32).abs() < TOL);
        }
        for i in j + 1..m {
            assert_eq!(cu[i + j * m], 0.0);
        }
    }
}

#[test]
fn ssyevr_spotrf_spotrs_sgesv() {
    let mut r = rng(21);
    let n = 6usize;
    let ni = n as i32;
    let s = rand_sym(&mut r, n, n);
    let reference = jacobi_eigenvalues(&s, n, n);
    let mut a = to32(&s);
    let mut w = vec![0f32; n];
    let mut z = vec![0f32; n * n];
    let mut isuppz = vec![0i32; 2 * n];
    let mut work = vec![0f32; 1];
    let mut iwork = vec![0i32; 1];
    let (mut m, mut info) = (0i32, 0i32);
    unsafe {
        ssyevr_(
            &ch(b'V'),
            &ch(b'A'),
            &ch(b'U'),
            &ni,
            a.as_mut_ptr(),
            &ni,
            &0.0,
            &0.0,
            &0,
            &0,
            &-1.0,
            &mut m,
            w.as_mut_ptr(),
            z.as_mut_ptr(),
            &ni,
            isuppz.as_mut_ptr(),
            work.as_mut_ptr(),
            &-1,
            iwork.as_mut_ptr(),
            &-1,
            &mut info,
        )
    };
    assert_eq!(info, 0);
    let (lw, liw) = (work[0] as i32, iwork[0]);
    work.resize(lw as usize, 0.0);
    iwork.resize(liw as usize, 0);
    unsafe {
        ssyevr_(
            &ch(b'V'),
            &ch(b'A'),
            &ch(b'U'),
            &ni,
            a.as_mut_ptr(),
            &ni,
            &0.0,
            &0.0,
            &0,
            &0,
            &-1.0,
            &mut m,
            w.as_mut_ptr(),
            z.as_mut_ptr(),
            &ni,
            isuppz.as_mut_ptr(),
            work.as_mut_ptr(),
            &lw,
            iwork.as_mut_ptr(),
            &liw,
            &mut info,
        )
    };
    assert_eq!((info, m), (0, ni));
    for i in 0..n {
        assert!((w[i] - reference[i] as f32).abs() < TOL);
    }

    let p = rand_spd(&mut r, n, n);
    let mut f = to32(&p);
    unsafe { spotrf_(&ch(b'L'), &ni, f.as_mut_ptr(), &ni, &mut info) };
    assert_eq!(info, 0);
    let x = rand_mat(&mut r, n, 1, n);
    let mut b = to32(&naive_mul(&p, n, &x, n, n, n, 1));
    unsafe {
        spotrs_(
            &ch(b'L'),
            &ni,
            &1,
            f.as_ptr(),
            &ni,
            b.as_mut_ptr(),
            &ni,
            &mut info,
        )
    };
    assert_eq!(info, 0);
    for i in 0..n {
        assert!((b[i] - x[i] as f32).abs() < TOL);
    }

    let g = rand_spd(&mut r, n, n); // well conditioned
    let mut f = to32(&g);
    let mut b = to32(&naive_mul(&g, n, &x, n, n, n, 1));
    let mut ipiv = vec![0i32; n];
    unsafe {
        sgesv_(
            &ni,
            &1,
            f.as_mut_ptr(),
            &ni,
            ipiv.as_mut_ptr(),
            b.as_mut_ptr(),
            &ni,
            &mut info,
        )
    };
    assert_eq!(info, 0);
    for i in 0..n {
        assert!((b[i] - x[i] as f32).abs() < TOL);
    }
}

#[test]
fn sgesdd_sgesvd() {
    let mut r = rng(22);
    let (m, n) = (6usize, 4usize);
    let a = rand_mat(&mut r, m, n, m);
    let ata = naive_mul(&transpose(&a, m, m, n), n, &a, m, n, m, n);
    let mut ev = jacobi_eigenvalues(&ata, n, n);
    ev.reverse();
    let (mi, ni) = (m as i32, n as i32);
    for dd in [true, false] {
        let mut f = to32(&a);
        let mut s = vec![0f32; n];
        let mut u = vec![0f32; m * n];
        let mut vt = vec![0f32; n * n];
        let mut work = vec![0f32; 1];
        let mut iwork = vec![0i32; 8 * n];
        let mut info = 0;
        for pass in 0..2 {
            let lwork = if pass == 0 { -1 } else { work[0] as i32 };
            if pass == 1 {
                work.resize(lwork as usize, 0.0);
            }
            if dd {
                unsafe {
                    sgesdd_(
                        &ch(b'S'),
                        &mi,
                        &ni,
                        f.as_mut_ptr(),
                        &mi,
                        s.as_mut_ptr(),
                        u.as_mut_ptr(),
                        &mi,
                        vt.as_mut_ptr(),
                        &ni,
                        work.as_mut_ptr(),
                        &lwork,
                        iwork.as_mut_ptr(),
                        &mut info,
                    )
                };
            } else {
                unsafe {
                    sgesvd_(
                        &ch(b'S'),
                        &ch(b'S'),
                        &mi,
                        &ni,
                        f.as_mut_ptr(),
                        &mi,
                        s.as_mut_ptr(),
                        u.as_mut_ptr(),
                        &mi,
                        vt.as_mut_ptr(),
                        &ni,
                        work.as_mut_ptr(),
                        &lwork,
                        &mut info,
                    )
                };
            }
            assert_eq!(info, 0);
        }
        for i in 0..n {
            assert!((s[i] - ev[i].sqrt() as f32).abs() < TOL);
        }
        for j in 0..n {
            for i in 0..m {
                let rec: f32 = (0..n).map(|l| u[i + l * m] * s[l] * vt[l + j * n]).sum();
                assert!((rec - a[i + j * m] as f32).abs() < TOL);
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
