//! Test-only helpers shared by the geometry integration tests: dense row-major matrix helpers, a cyclic Jacobi
//! eigensolver (independent of faer, which the library uses), random rotations, and the global brute force for
//! the ellipsoid boundary-distance problem (7.2).
#![allow(dead_code, non_snake_case)]

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

pub fn matmul(A: &[f64], B: &[f64], m: usize, k: usize, n: usize) -> Vec<f64> {
    let mut C = vec![0.0; m * n];
    for i in 0..m {
        for l in 0..k {
            for j in 0..n {
                C[i * n + j] += A[i * k + l] * B[l * n + j];
            }
        }
    }
    C
}

pub fn transpose(A: &[f64], m: usize, n: usize) -> Vec<f64> {
    let mut T = vec![0.0; m * n];
    for i in 0..m {
        for j in 0..n {
            T[j * m + i] = A[i * n + j];
        }
    }
    T
}

pub fn matvec(A: &[f64], m: usize, n: usize, x: &[f64]) -> Vec<f64> {
    (0..m)
        .map(|i| (0..n).map(|j| A[i * n + j] * x[j]).sum())
        .collect()
}

pub fn quad(A: &[f64], v: &[f64]) -> f64 {
    let n = v.len();
    let Av = matvec(A, n, n, v);
    v.iter().zip(&Av).map(|(a, b)| a * b).sum()
}

/// |v|ᵀ|A||v|: the scale of the rounding error when vᵀAv is evaluated.
pub fn abs_quad(A: &[f64], v: &[f64]) -> f64 {
    let n = v.len();
    let mut s = 0.0;
    for i in 0..n {
        for j in 0..n {
            s += (v[i] * A[i * n + j] * v[j]).abs();
        }
    }
    s
}

pub fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0_f64, |m, x| m.max(x.abs()))
}

pub fn rdist(R: &[f64], x: &[f64], y: &[f64]) -> f64 {
    let d: Vec<f64> = x.iter().zip(y).map(|(a, b)| a - b).collect();
    quad(R, &d).max(0.0).sqrt()
}

/// Cyclic Jacobi eigendecomposition of a symmetric matrix: (eigenvalues, V row-major with eigenvectors as
/// columns), unsorted. Independent of the library's faer-based eigensolver.
pub fn jacobi(n: usize, A: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut a = A.to_vec();
    for i in 0..n {
        for j in 0..i {
            let m = 0.5 * (a[i * n + j] + a[j * n + i]);
            a[i * n + j] = m;
            a[j * n + i] = m;
        }
    }
    let mut v = vec![0.0; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i * n + j].powi(2))
            .sum();
        let diag: f64 = (0..n).map(|i| a[i * n + i].powi(2)).sum();
        if off == 0.0 || off <= 1e-34 * diag {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = a[p * n + q];
                if apq == 0.0 {
                    continue;
                }
                let theta = (a[q * n + q] - a[p * n + p]) / (2.0 * apq);
                let sign = if theta >= 0.0 { 1.0 } else { -1.0 };
                let t = if theta.abs() > 1e150 {
                    0.5 / theta
                } else {
                    sign / (theta.abs() + (theta * theta + 1.0).sqrt())
                };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (a[k * n + p], a[k * n + q]);
                    a[k * n + p] = c * akp - s * akq;
                    a[k * n + q] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[p * n + k], a[q * n + k]);
                    a[p * n + k] = c * apk - s * aqk;
                    a[q * n + k] = s * apk + c * aqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let w = (0..n).map(|i| a[i * n + i]).collect();
    (w, v)
}

/// Pseudo-inverse of a symmetric matrix by Jacobi, eigenvalues below 1e-12·max|λ| dropped.
pub fn pinv_sym(n: usize, A: &[f64]) -> Vec<f64> {
    if n == 0 {
        return vec![];
    }
    let (w, V) = jacobi(n, A);
    let big = w.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    let mut P = vec![0.0; n * n];
    for k in 0..n {
        if w[k].abs() <= 1e-12 * big || w[k] == 0.0 {
            continue;
        }
        for i in 0..n {
            for j in 0..n {
                P[i * n + j] += V[i * n + k] * V[j * n + k] / w[k];
            }
        }
    }
    P
}

/// A uniformly random rotation (Gram–Schmidt on a Gaussian matrix), row-major.
pub fn random_orthogonal(n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    loop {
        let mut cols: Vec<Vec<f64>> = Vec::with_capacity(n);
        let mut ok = true;
        for _ in 0..n {
            let mut v: Vec<f64> = (0..n)
                .map(|_| rng.sample::<f64, _>(StandardNormal))
                .collect();
            for _ in 0..2 {
                for u in &cols {
                    let d: f64 = v.iter().zip(u).map(|(a, b)| a * b).sum();
                    for (vi, ui) in v.iter_mut().zip(u) {
                        *vi -= d * ui;
                    }
                }
            }
            let nv = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if nv < 1e-6 {
                ok = false;
                break;
            }
            cols.push(v.iter().map(|x| x / nv).collect());
        }
        if ok {
            let mut V = vec![0.0; n * n];
            for (j, c) in cols.iter().enumerate() {
                for i in 0..n {
                    V[i * n + j] = c[i];
                }
            }
            return V;
        }
    }
}

/// V diag(d) Vᵀ.
pub fn compose(n: usize, V: &[f64], d: &[f64]) -> Vec<f64> {
    let mut A = vec![0.0; n * n];
    for k in 0..n {
        for i in 0..n {
            for j in 0..n {
                A[i * n + j] += V[i * n + k] * d[k] * V[j * n + k];
            }
        }
    }
    // exact symmetry
    for i in 0..n {
        for j in 0..i {
            let m = 0.5 * (A[i * n + j] + A[j * n + i]);
            A[i * n + j] = m;
            A[j * n + i] = m;
        }
    }
    A
}

/// The brute-force answer: the best feasible boundary point found and its R-distance.
#[derive(Debug, Clone)]
pub struct Brute {
    pub value: f64,
    pub point: Vec<f64>,
    pub candidates: usize,
}

/// Global minimum of ‖x − x̄‖_R over {x : (x − c)ᵀQ(x − c) = 1}, by an independent route:
///
/// 1. Parametrise the boundary with Q's eigenvectors (Jacobi): x = c + F s + N t, ‖s‖ = 1, where F whitens the
///    range of Q and N spans its null space (t free).
/// 2. Minimise over t in closed form (convex least squares, pseudo-inverse), leaving
///    φ(s) = sᵀAs − 2bᵀs + const on the unit sphere (a trust-region-type problem; A may be singular).
/// 3. Every minimiser on the sphere satisfies (A − θI)s = b. In A's eigenbasis: either θ is no eigenvalue and
///    ψ(θ) = Σ βᵢ²/(dᵢ − θ)² − 1 = 0, found by a dense scan of every interval between poles (plus both
///    unbounded ends) with bisection at every sign change and a golden-section refinement of each interval's
///    minimum (tangential roots); or θ = d_j with the components off that eigenvalue fixed and the rest on a
///    sphere (degenerate candidates). All candidates are feasible; the best one is returned.
pub fn brute_force(c: &[f64], Q: &[f64], R: &[f64], xbar: &[f64]) -> Brute {
    let n = c.len();
    let (sig, V) = jacobi(n, Q);
    let smax = sig.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    let pos: Vec<usize> = (0..n).filter(|&i| sig[i] > 1e-12 * smax).collect();
    let nul: Vec<usize> = (0..n).filter(|i| !pos.contains(i)).collect();
    let (q, k) = (pos.len(), nul.len());
    let mut F = vec![0.0; n * q];
    for (a, &j) in pos.iter().enumerate() {
        for i in 0..n {
            F[i * q + a] = V[i * n + j] / sig[j].sqrt();
        }
    }
    let mut Nb = vec![0.0; n * k];
    for (a, &j) in nul.iter().enumerate() {
        for i in 0..n {
            Nb[i * k + a] = V[i * n + j];
        }
    }
    let g: Vec<f64> = xbar.iter().zip(c).map(|(a, b)| a - b).collect();
    // t = −H (F s − g), H = (NᵀRN)⁺ NᵀR; R̃ = R − R N (NᵀRN)⁺ NᵀR.
    let Nt = transpose(&Nb, n, k);
    let NtR = matmul(&Nt, R, k, n, n);
    let NRN = matmul(&NtR, &Nb, k, n, k);
    let NRNp = pinv_sym(k, &NRN);
    let H = matmul(&NRNp, &NtR, k, k, n);
    let RN = transpose(&NtR, k, n);
    let corr = matmul(&RN, &H, n, k, n);
    let Rt: Vec<f64> = R.iter().zip(&corr).map(|(a, b)| a - b).collect();
    let Ft = transpose(&F, n, q);
    let A = matmul(&matmul(&Ft, &Rt, q, n, n), &F, q, n, q);
    let b = matvec(&matmul(&Ft, &Rt, q, n, n), q, n, &g);
    let (d, W) = jacobi(q, &A);
    let beta: Vec<f64> = (0..q)
        .map(|i| (0..q).map(|r| W[r * q + i] * b[r]).sum())
        .collect();

    let mut sigmas: Vec<Vec<f64>> = Vec::new();
    let from_theta = |theta: f64| -> Option<Vec<f64>> {
        let s: Vec<f64> = (0..q)
            .map(|i| {
                if beta[i] == 0.0 {
                    0.0
                } else {
                    beta[i] / (d[i] - theta)
                }
            })
            .collect();
        let ns = s.iter().map(|x| x * x).sum::<f64>().sqrt();
        (ns > 0.0 && ns.is_finite()).then(|| s.iter().map(|x| x / ns).collect())
    };
    let psi = |theta: f64| -> f64 {
        (0..q)
            .filter(|&i| beta[i] != 0.0)
            .map(|i| (beta[i] / (d[i] - theta)).powi(2))
            .sum::<f64>()
            - 1.0
    };
    let mut poles: Vec<f64> = (0..q).filter(|&i| beta[i] != 0.0).map(|i| d[i]).collect();
    poles.sort_by(|a, b| a.total_cmp(b));
    poles.dedup();
    if !poles.is_empty() {
        let L = 2.0 * (beta.iter().map(|x| x * x).sum::<f64>().sqrt() + 1.0);
        // (lo, hi, lo_is_pole, hi_is_pole)
        let mut intervals = vec![(poles[0] - L, poles[0], false, true)];
        for w in poles.windows(2) {
            intervals.push((w[0], w[1], true, true));
        }
        intervals.push((
            poles[poles.len() - 1],
            poles[poles.len() - 1] + L,
            true,
            false,
        ));
        const K: usize = 400;
        for &(a, bnd, a_pole, b_pole) in &intervals {
            if bnd.is_nan() || bnd <= a {
                continue;
            }
            let mut pts: Vec<(f64, f64)> = Vec::with_capacity(K + 1);
            pts.push((a, if a_pole { f64::INFINITY } else { psi(a) }));
            for kk in 1..K {
                let th = a
                    + (bnd - a) * 0.5 * (1.0 - (std::f64::consts::PI * kk as f64 / K as f64).cos());
                if th > a && th < bnd {
                    pts.push((th, psi(th)));
                }
            }
            pts.push((bnd, if b_pole { f64::INFINITY } else { psi(bnd) }));
            // Sign changes → bisection.
            for w in pts.windows(2) {
                let ((mut lo, flo), (mut hi, fhi)) = (w[0], w[1]);
                if (flo > 0.0) == (fhi > 0.0) {
                    continue;
                }
                let lo_pos = flo > 0.0;
                for _ in 0..300 {
                    let mid = 0.5 * (lo + hi);
                    if mid <= lo || mid >= hi {
                        break;
                    }
                    if (psi(mid) > 0.0) == lo_pos {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                for th in [lo, hi] {
                    if th != a || !a_pole {
                        if let Some(s) = from_theta(th) {
                            sigmas.push(s);
                        }
                    }
                }
            }
            // Interval minimum (tangential roots): golden section around the grid minimum.
            let interior: Vec<usize> = (1..pts.len() - 1).collect();
            if let Some(&im) = interior
                .iter()
                .min_by(|&&i, &&j| pts[i].1.total_cmp(&pts[j].1))
            {
                let (mut lo, mut hi) = (pts[im - 1].0, pts[im + 1].0);
                let gr = 0.5 * (5.0_f64.sqrt() - 1.0);
                for _ in 0..200 {
                    let x1 = hi - gr * (hi - lo);
                    let x2 = lo + gr * (hi - lo);
                    if !(x1 > lo && x2 < hi && x1 < x2) {
                        break;
                    }
                    if psi(x1) < psi(x2) {
                        hi = x2;
                    } else {
                        lo = x1;
                    }
                }
                let th = 0.5 * (lo + hi);
                if psi(th) <= 1e-6 {
                    if let Some(s) = from_theta(th) {
                        sigmas.push(s);
                    }
                }
            }
        }
    }
    // Degenerate candidates θ = d_j.
    let dscale = d.iter().fold(0.0_f64, |m, x| m.max(x.abs())).max(1e-300);
    for j in 0..q {
        let J: Vec<usize> = (0..q)
            .filter(|&i| (d[i] - d[j]).abs() <= 1e-12 * dscale)
            .collect();
        let mut s = vec![0.0; q];
        let mut used = 0.0;
        for i in 0..q {
            if !J.contains(&i) {
                s[i] = beta[i] / (d[i] - d[j]);
                used += s[i] * s[i];
            }
        }
        let r2 = 1.0 - used;
        if r2 < -1e-12 || !r2.is_finite() {
            continue;
        }
        let r = r2.max(0.0).sqrt();
        let nbJ = J.iter().map(|&i| beta[i] * beta[i]).sum::<f64>().sqrt();
        for sign in [1.0, -1.0] {
            let mut t = s.clone();
            for &i in &J {
                t[i] = sign
                    * r
                    * if nbJ > 0.0 {
                        beta[i] / nbJ
                    } else if i == J[0] {
                        1.0
                    } else {
                        0.0
                    };
            }
            let nt = t.iter().map(|x| x * x).sum::<f64>().sqrt();
            if nt > 0.0 {
                sigmas.push(t.iter().map(|x| x / nt).collect());
            }
        }
    }

    let mut best = Brute {
        value: f64::INFINITY,
        point: vec![],
        candidates: sigmas.len(),
    };
    for sg in &sigmas {
        let s = matvec(&W, q, q, sg);
        let Fs = matvec(&F, n, q, &s);
        let y: Vec<f64> = Fs.iter().zip(&g).map(|(a, b)| a - b).collect();
        let t: Vec<f64> = matvec(&H, k, n, &y).iter().map(|v| -v).collect();
        let Nt_ = matvec(&Nb, n, k, &t);
        let x: Vec<f64> = (0..n).map(|i| c[i] + Fs[i] + Nt_[i]).collect();
        let v = rdist(R, &x, xbar);
        if v < best.value {
            best.value = v;
            best.point = x;
        }
    }
    best
}
