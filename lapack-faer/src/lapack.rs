//! LAPACK drivers (`?syevr`, `?potrf`, `?potrs`, `?gesv`, `?gesdd`, `?gesvd`) on faer's decompositions.
//!
//! Kept from reference LAPACK: argument checks in the documented order with `info = -i`, workspace queries
//! (`lwork = -1` / `liwork = -1` return the sizes in `work[0]` / `iwork[0]`), the documented minimum workspace
//! sizes (a caller that would fail with a real LAPACK fails here too), every `jobz`/`range`/`uplo`/`jobu`/
//! `jobvt` variant, leading dimensions, and positive `info` for numerical failure.
//!
//! Deliberate differences, all within what LAPACK's documentation allows a caller to rely on:
//! - the `work`/`iwork` arrays are not used as scratch (faer allocates its own); they are only sized/queried;
//! - `?syevr` ignores `abstol` (faer's symmetric eigensolver works to full precision) and leaves `A` intact;
//!   `isuppz` reports the exact first/last nonzero row of each returned eigenvector;
//! - `?gesdd`/`?gesvd` leave `A` intact unless a `'O'` job asks for a factor to be written over it;
//! - a non-finite entry in the input of `?syevr`/`?gesdd`/`?gesvd` is reported as `info = 1` (no
//!   convergence) rather than iterating on NaNs;
//! - `?gesv` with an exactly singular `U` reports `info = i` like LAPACK, but the multipliers below the zero
//!   pivot may be non-finite (LAPACK leaves them unscaled); no solution is computed in that case either way.

use crate::scalar::*;
use core::ffi::c_char;
use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch, LltError};
use faer::linalg::evd::{self_adjoint_evd, self_adjoint_evd_scratch, ComputeEigenvectors};
use faer::linalg::lu::partial_pivoting::factor::{lu_in_place, lu_in_place_scratch};
use faer::linalg::svd::{svd, svd_scratch, ComputeSvdVectors};
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_unit_lower_triangular_in_place,
    solve_upper_triangular_in_place,
};
use faer::reborrow::*;
use faer::{Mat, MatRef, Par};

fn all_finite<T: Real>(a: MatRef<'_, T>) -> bool {
    (0..a.ncols()).all(|j| (0..a.nrows()).all(|i| a[(i, j)].finite()))
}

/// Write `src` into column-major storage at `dst` with leading dimension `ld`.
///
/// # Safety
/// `dst` must be valid for `ld * (ncols - 1) + nrows` writes.
unsafe fn store<T: Real>(src: MatRef<'_, T>, dst: *mut T, ld: usize) {
    let mut d = unsafe { mat_mut(dst, src.nrows(), src.ncols(), ld) };
    for j in 0..src.ncols() {
        for i in 0..src.nrows() {
            d[(i, j)] = src[(i, j)];
        }
    }
}

/// `?syevr`: eigenvalues (and optionally eigenvectors) of a symmetric matrix, all of them, those in the
/// half-open interval `(vl, vu]`, or those with (1-based, ascending) indices `il..=iu`.
///
/// # Safety
/// Fortran calling convention: every pointer valid for the sizes the arguments describe.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn syevr<T: Real>(
    name: &str,
    jobz: *const c_char,
    range: *const c_char,
    uplo: *const c_char,
    n: *const i32,
    a: *mut T,
    lda: *const i32,
    vl: *const T,
    vu: *const T,
    il: *const i32,
    iu: *const i32,
    _abstol: *const T,
    m: *mut i32,
    w: *mut T,
    z: *mut T,
    ldz: *const i32,
    isuppz: *mut i32,
    work: *mut T,
    lwork: *const i32,
    iwork: *mut i32,
    liwork: *const i32,
    info: *mut i32,
) {
    let (jz, rg, ul) = unsafe { (flag(jobz), flag(range), flag(uplo)) };
    let (n, lda, ldz, lwork, liwork) =
        unsafe { (int(n), int(lda), int(ldz), int(lwork), int(liwork)) };
    let wantz = jz == b'V';
    let (alleig, valeig, indeig) = (rg == b'A', rg == b'V', rg == b'I');
    let lquery = lwork == -1 || liwork == -1;
    let lwmin = (26 * n).max(1);
    let liwmin = (10 * n).max(1);
    let mut e = 0;
    if !(wantz || jz == b'N') {
        e = -1;
    } else if !(alleig || valeig || indeig) {
        e = -2;
    } else if !(ul == b'L' || ul == b'U') {
        e = -3;
    } else if n < 0 {
        e = -4;
    } else if lda < max1(n) {
        e = -6;
    } else if valeig && n > 0 && unsafe { val(vu) <= val(vl) } {
        e = -8;
    } else if indeig {
        let (il, iu) = unsafe { (int(il), int(iu)) };
        if il < 1 || il > max1(n) {
            e = -9;
        } else if iu < n.min(il) || iu > n {
            e = -10;
        }
    }
    if e == 0 && (ldz < 1 || (wantz && ldz < n)) {
        e = -15;
    }
    if e == 0 {
        unsafe {
            *work = T::from_usize(lwmin as usize);
            *iwork = liwmin;
        }
        if lwork < lwmin && !lquery {
            e = -18;
        } else if liwork < liwmin && !lquery {
            e = -20;
        }
    }
    unsafe { *info = e };
    if e != 0 {
        xerbla(name, -e);
        return;
    }
    if lquery {
        return;
    }
    unsafe { *m = 0 };
    if n == 0 {
        return;
    }
    let nu = n as usize;
    let am = unsafe { mat_ref(a as *const T, nu, nu, lda as usize) };
    // faer reads the lower triangle; the lower triangle of Aᵀ is the upper triangle of A.
    let src = if ul == b'U' { am.transpose() } else { am };
    let lower_ok = (0..nu).all(|j| (j..nu).all(|i| src[(i, j)].finite()));
    if !lower_ok {
        unsafe { *info = 1 };
        return;
    }
    let par = Par::Seq;
    let compute = if wantz {
        ComputeEigenvectors::Yes
    } else {
        ComputeEigenvectors::No
    };
    let mut s = Diag::<T>::zeros(nu);
    let mut u = Mat::<T>::zeros(if wantz { nu } else { 0 }, if wantz { nu } else { 0 });
    let mut mem = MemBuffer::new(self_adjoint_evd_scratch::<T>(
        nu,
        compute,
        par,
        Default::default(),
    ));
    let res = self_adjoint_evd(
        src,
        s.as_mut(),
        if wantz { Some(u.as_mut()) } else { None },
        par,
        MemStack::new(&mut mem),
        Default::default(),
    );
    if res.is_err() {
        unsafe { *info = 1 };
        return;
    }
    let lam = s.column_vector();
    let selected: Vec<usize> = if alleig {
        (0..nu).collect()
    } else if valeig {
        let (vl, vu) = unsafe { (val(vl), val(vu)) };
        (0..nu).filter(|&i| lam[i] > vl && lam[i] <= vu).collect()
    } else {
        let (il, iu) = unsafe { (int(il) as usize, int(iu) as usize) };
        (il - 1..iu).collect()
    };
    unsafe { *m = selected.len() as i32 };
    for (k, &i) in selected.iter().enumerate() {
        unsafe { *w.add(k) = lam[i] };
    }
    if wantz {
        let mut zm = unsafe { mat_mut(z, nu, selected.len(), ldz as usize) };
        for (k, &i) in selected.iter().enumerate() {
            let mut first = 0usize;
            let mut last = 0usize;
            let mut seen = false;
            for r in 0..nu {
                let v = u[(r, i)];
                zm[(r, k)] = v;
                if v != T::ZERO {
                    if !seen {
                        first = r;
                        seen = true;
                    }
                    last = r;
                }
            }
            unsafe {
                *isuppz.add(2 * k) = first as i32 + 1;
                *isuppz.add(2 * k + 1) = last as i32 + 1;
            }
        }
    }
}

/// `?potrf`: Cholesky factorisation `A = UᵀU` (`uplo = 'U'`) or `A = LLᵀ` (`'L'`); only that triangle is read
/// and written. `info = i > 0`: the leading minor of order `i` is not positive definite (`A` left unchanged).
///
/// # Safety
/// Fortran calling convention: every pointer valid for the sizes the arguments describe.
pub(crate) unsafe fn potrf<T: Real>(
    name: &str,
    uplo: *const c_char,
    n: *const i32,
    a: *mut T,
    lda: *const i32,
    info: *mut i32,
) {
    let ul = unsafe { flag(uplo) };
    let (n, lda) = unsafe { (int(n), int(lda)) };
    let e = if !(ul == b'U' || ul == b'L') {
        -1
    } else if n < 0 {
        -2
    } else if lda < max1(n) {
        -4
    } else {
        0
    };
    unsafe { *info = e };
    if e != 0 {
        xerbla(name, -e);
        return;
    }
    if n == 0 {
        return;
    }
    let nu = n as usize;
    let upper = ul == b'U';
    let mut am = unsafe { mat_mut(a, nu, nu, lda as usize) };
    // Work on a dense lower-triangular copy so the untouched triangle of the caller's matrix stays untouched.
    let mut l = Mat::<T>::zeros(nu, nu);
    for j in 0..nu {
        for i in j..nu {
            l[(i, j)] = if upper { am[(j, i)] } else { am[(i, j)] };
        }
    }
    let par = Par::Seq;
    let mut mem = MemBuffer::new(cholesky_in_place_scratch::<T>(nu, par, Default::default()));
    match cholesky_in_place(
        l.as_mut(),
        Default::default(),
        par,
        MemStack::new(&mut mem),
        Default::default(),
    ) {
        Ok(_) => {
            for j in 0..nu {
                for i in j..nu {
                    if upper {
                        am[(j, i)] = l[(i, j)];
                    } else {
                        am[(i, j)] = l[(i, j)];
                    }
                }
            }
        }
        Err(LltError::NonPositivePivot { index }) => unsafe { *info = index as i32 + 1 },
    }
}

/// `?potrs`: solve `A X = B` with the factor from `?potrf` (same `uplo`); `B` is overwritten by `X`.
///
/// # Safety
/// Fortran calling convention: every pointer valid for the sizes the arguments describe.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn potrs<T: Real>(
    name: &str,
    uplo: *const c_char,
    n: *const i32,
    nrhs: *const i32,
    a: *const T,
    lda: *const i32,
    b: *mut T,
    ldb: *const i32,
    info: *mut i32,
) {
    let ul = unsafe { flag(uplo) };
    let (n, nrhs, lda, ldb) = unsafe { (int(n), int(nrhs), int(lda), int(ldb)) };
    let e = if !(ul == b'U' || ul == b'L') {
        -1
    } else if n < 0 {
        -2
    } else if nrhs < 0 {
        -3
    } else if lda < max1(n) {
        -5
    } else if ldb < max1(n) {
        -7
    } else {
        0
    };
    unsafe { *info = e };
    if e != 0 {
        xerbla(name, -e);
        return;
    }
    if n == 0 || nrhs == 0 {
        return;
    }
    let nu = n as usize;
    let am = unsafe { mat_ref(a, nu, nu, lda as usize) };
    // A = L Lᵀ with L = tril(A) (uplo 'L') or L = triu(A)ᵀ (uplo 'U').
    let l = if ul == b'U' { am.transpose() } else { am };
    let mut bm = unsafe { mat_mut(b, nu, nrhs as usize, ldb as usize) };
    solve_lower_triangular_in_place(l, bm.rb_mut(), Par::Seq);
    solve_upper_triangular_in_place(l.transpose(), bm, Par::Seq);
}

/// `?gesv`: LU factorisation with partial pivoting `A = P L U` (factors and 1-based row interchanges `ipiv`
/// as LAPACK stores them) and solution of `A X = B`. `info = i > 0`: `U(i,i)` is exactly zero, no solution.
///
/// # Safety
/// Fortran calling convention: every pointer valid for the sizes the arguments describe.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn gesv<T: Real>(
    name: &str,
    n: *const i32,
    nrhs: *const i32,
    a: *mut T,
    lda: *const i32,
    ipiv: *mut i32,
    b: *mut T,
    ldb: *const i32,
    info: *mut i32,
) {
    let (n, nrhs, lda, ldb) = unsafe { (int(n), int(nrhs), int(lda), int(ldb)) };
    let e = if n < 0 {
        -1
    } else if nrhs < 0 {
        -2
    } else if lda < max1(n) {
        -4
    } else if ldb < max1(n) {
        -7
    } else {
        0
    };
    unsafe { *info = e };
    if e != 0 {
        xerbla(name, -e);
        return;
    }
    if n == 0 {
        return;
    }
    let nu = n as usize;
    let mut am = unsafe { mat_mut(a, nu, nu, lda as usize) };
    let mut perm = vec![0usize; nu];
    let mut perm_inv = vec![0usize; nu];
    let par = Par::Seq;
    let mut mem = MemBuffer::new(lu_in_place_scratch::<usize, T>(
        nu,
        nu,
        par,
        Default::default(),
    ));
    let _ = lu_in_place(
        am.rb_mut(),
        &mut perm,
        &mut perm_inv,
        par,
        MemStack::new(&mut mem),
        Default::default(),
    );
    // faer returns the final row permutation (row i of P A is row perm[i] of A); LAPACK wants the sequence of
    // interchanges that produces it: at step i, swap row i with the row currently holding perm[i].
    let mut cur: Vec<usize> = (0..nu).collect(); // cur[position] = original row
    let mut pos: Vec<usize> = (0..nu).collect(); // pos[original row] = position
    for i in 0..nu {
        let j = pos[perm[i]];
        unsafe { *ipiv.add(i) = j as i32 + 1 };
        let (ri, rj) = (cur[i], cur[j]);
        cur.swap(i, j);
        pos[ri] = j;
        pos[rj] = i;
    }
    if let Some(i) = (0..nu).find(|&i| am[(i, i)] == T::ZERO) {
        unsafe { *info = i as i32 + 1 };
        return;
    }
    if nrhs == 0 {
        return;
    }
    let mut bm = unsafe { mat_mut(b, nu, nrhs as usize, ldb as usize) };
    for i in 0..nu {
        let p = unsafe { *ipiv.add(i) } as usize - 1;
        if p != i {
            for c in 0..nrhs as usize {
                let t = bm[(i, c)];
                bm[(i, c)] = bm[(p, c)];
                bm[(p, c)] = t;
            }
        }
    }
    let lu = am.rb();
    solve_unit_lower_triangular_in_place(lu, bm.rb_mut(), par);
    solve_upper_triangular_in_place(lu, bm, par);
}

/// The factors of one SVD, computed by faer into owned storage (so `'O'` jobs can overwrite `A` afterwards).
struct SvdParts<T> {
    s: Diag<T>,
    u: Option<Mat<T>>,
    v: Option<Mat<T>>,
}

fn svd_parts<T: Real>(
    a: MatRef<'_, T>,
    ju: ComputeSvdVectors,
    jv: ComputeSvdVectors,
) -> Option<SvdParts<T>> {
    let (m, n) = a.shape();
    let k = m.min(n);
    let cols = |job: ComputeSvdVectors, full: usize| match job {
        ComputeSvdVectors::No => None,
        ComputeSvdVectors::Thin => Some(k),
        ComputeSvdVectors::Full => Some(full),
    };
    let mut s = Diag::<T>::zeros(k);
    let mut u = cols(ju, m).map(|c| Mat::<T>::zeros(m, c));
    let mut v = cols(jv, n).map(|c| Mat::<T>::zeros(n, c));
    let par = Par::Seq;
    let mut mem = MemBuffer::new(svd_scratch::<T>(m, n, ju, jv, par, Default::default()));
    let res = svd(
        a,
        s.as_mut(),
        u.as_mut().map(|u| u.as_mut()),
        v.as_mut().map(|v| v.as_mut()),
        par,
        MemStack::new(&mut mem),
        Default::default(),
    );
    res.ok().map(|_| SvdParts { s, u, v })
}

/// `?gesdd`: singular value decomposition `A = U Σ Vᵀ`, `jobz ∈ {A, S, O, N}`.
///
/// # Safety
/// Fortran calling convention: every pointer valid for the sizes the arguments describe.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn gesdd<T: Real>(
    name: &str,
    jobz: *const c_char,
    m: *const i32,
    n: *const i32,
    a: *mut T,
    lda: *const i32,
    s: *mut T,
    u: *mut T,
    ldu: *const i32,
    vt: *mut T,
    ldvt: *const i32,
    work: *mut T,
    lwork: *const i32,
    _iwork: *mut i32,
    info: *mut i32,
) {
    let jz = unsafe { flag(jobz) };
    let (m, n, lda, ldu, ldvt, lwork) =
        unsafe { (int(m), int(n), int(lda), int(ldu), int(ldvt), int(lwork)) };
    let (wa, ws, wo, wn) = (jz == b'A', jz == b'S', jz == b'O', jz == b'N');
    let mn = m.min(n);
    let mx = m.max(n);
    let lquery = lwork == -1;
    let mut e = 0;
    if !(wa || ws || wo || wn) {
        e = -1;
    } else if m < 0 {
        e = -2;
    } else if n < 0 {
        e = -3;
    } else if lda < max1(m) {
        e = -5;
    } else if ldu < 1 || ((wa || ws || (wo && m < n)) && ldu < m) {
        e = -8;
    } else if ldvt < 1 || (wa && ldvt < n) || (ws && ldvt < mn) || (wo && m >= n && ldvt < n) {
        e = -10;
    }
    if e == 0 {
        // The minimum sizes LAPACK documents for ?gesdd.
        let minwrk = if m == 0 || n == 0 {
            1
        } else if wn {
            3 * mn + mx.max(7 * mn)
        } else if wo {
            3 * mn + mx.max(5 * mn * mn + 4 * mn)
        } else if ws {
            4 * mn * mn + 7 * mn
        } else {
            4 * mn * mn + 6 * mn + mx
        };
        unsafe { *work = T::from_usize(minwrk.max(1) as usize) };
        if lwork < minwrk.max(1) && !lquery {
            e = -12;
        }
    }
    unsafe { *info = e };
    if e != 0 {
        xerbla(name, -e);
        return;
    }
    if lquery || m == 0 || n == 0 {
        return;
    }
    let (mu, nu) = (m as usize, n as usize);
    let am = unsafe { mat_ref(a as *const T, mu, nu, lda as usize) };
    if !all_finite(am) {
        unsafe { *info = 1 };
        return;
    }
    let job = if wn {
        ComputeSvdVectors::No
    } else if wa {
        ComputeSvdVectors::Full
    } else {
        ComputeSvdVectors::Thin
    };
    // 'O' with m < n needs the full U (m×m) and the thin Vᵀ; with m >= n the thin U and the full (n×n) Vᵀ.
    // Thin already is full for the square factor in both cases.
    let Some(p) = svd_parts(am, job, job) else {
        unsafe { *info = 1 };
        return;
    };
    let (ud, ldud) = if wo && mu >= nu { (a, lda) } else { (u, ldu) };
    let (vd, ldvd) = if wo && mu < nu { (a, lda) } else { (vt, ldvt) };
    unsafe { write_svd(&p, s, ud, ldud, vd, ldvd) };
}

/// Store singular values, `U` (if computed) and `Vᵀ` (if computed).
///
/// # Safety
/// Destinations valid for the factor shapes with their leading dimensions.
unsafe fn write_svd<T: Real>(
    p: &SvdParts<T>,
    s: *mut T,
    u: *mut T,
    ldu: i32,
    vt: *mut T,
    ldvt: i32,
) {
    let sv = p.s.column_vector();
    for i in 0..sv.nrows() {
        unsafe { *s.add(i) = sv[i] };
    }
    if let Some(um) = &p.u {
        unsafe { store(um.as_ref(), u, ldu as usize) };
    }
    if let Some(vm) = &p.v {
        unsafe { store(vm.as_ref().transpose(), vt, ldvt as usize) };
    }
}

/// `?gesvd`: singular value decomposition `A = U Σ Vᵀ`, `jobu, jobvt ∈ {A, S, O, N}` (not both `O`).
///
/// # Safety
/// Fortran calling convention: every pointer valid for the sizes the arguments describe.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn gesvd<T: Real>(
    name: &str,
    jobu: *const c_char,
    jobvt: *const c_char,
    m: *const i32,
    n: *const i32,
    a: *mut T,
    lda: *const i32,
    s: *mut T,
    u: *mut T,
    ldu: *const i32,
    vt: *mut T,
    ldvt: *const i32,
    work: *mut T,
    lwork: *const i32,
    info: *mut i32,
) {
    let (ju, jv) = unsafe { (flag(jobu), flag(jobvt)) };
    let (m, n, lda, ldu, ldvt, lwork) =
        unsafe { (int(m), int(n), int(lda), int(ldu), int(ldvt), int(lwork)) };
    let valid = |c: u8| matches!(c, b'A' | b'S' | b'O' | b'N');
    let mn = m.min(n);
    let lquery = lwork == -1;
    let mut e = 0;
    if !valid(ju) {
        e = -1;
    } else if !valid(jv) || (ju == b'O' && jv == b'O') {
        e = -2;
    } else if m < 0 {
        e = -3;
    } else if n < 0 {
        e = -4;
    } else if lda < max1(m) {
        e = -6;
    } else if ldu < 1 || (matches!(ju, b'A' | b'S') && ldu < m) {
        e = -9;
    } else if ldvt < 1 || (jv == b'A' && ldvt < n) || (jv == b'S' && ldvt < mn) {
        e = -11;
    }
    if e == 0 {
        // The minimum size LAPACK documents for ?gesvd.
        let minwrk = if m == 0 || n == 0 {
            1
        } else {
            (3 * mn + m.max(n)).max(5 * mn).max(1)
        };
        unsafe { *work = T::from_usize(minwrk as usize) };
        if lwork < minwrk && !lquery {
            e = -13;
        }
    }
    unsafe { *info = e };
    if e != 0 {
        xerbla(name, -e);
        return;
    }
    if lquery || m == 0 || n == 0 {
        return;
    }
    let (mu, nu) = (m as usize, n as usize);
    let am = unsafe { mat_ref(a as *const T, mu, nu, lda as usize) };
    if !all_finite(am) {
        unsafe { *info = 1 };
        return;
    }
    let job = |c: u8| match c {
        b'A' => ComputeSvdVectors::Full,
        b'N' => ComputeSvdVectors::No,
        _ => ComputeSvdVectors::Thin,
    };
    let Some(p) = svd_parts(am, job(ju), job(jv)) else {
        unsafe { *info = 1 };
        return;
    };
    let (ud, ldud) = if ju == b'O' { (a, lda) } else { (u, ldu) };
    let (vd, ldvd) = if jv == b'O' { (a, lda) } else { (vt, ldvt) };
    unsafe { write_svd(&p, s, ud, ldud, vd, ldvd) };
}
