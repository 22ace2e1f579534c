// scratch prototype (to be deleted): timing of LMI formulations in clarabel
#![allow(non_snake_case)]
use clarabel::algebra::*;
use clarabel::solver::*;
use lapack_faer as _;
use rand::{Rng, SeedableRng};
use std::time::Instant;

type M = Vec<Vec<f64>>;
fn z(r: usize, c: usize) -> M { vec![vec![0.0; c]; r] }

fn build(n: usize, m: usize, A: &M, B: &M, form: u8, sigma: f64) -> (usize, Vec<(usize, Box<dyn Fn(&[f64]) -> M>)>) {
    // vars: Q svec (nq), Y (m*n), s
    let nq = n * (n + 1) / 2;
    let nv = nq + m * n + 1;
    let unpack = move |x: &[f64]| {
        let mut Q = z(n, n);
        let mut k = 0;
        for j in 0..n { for i in 0..=j { Q[i][j] = x[k]; Q[j][i] = x[k]; k += 1; } }
        let mut Y = z(m, n);
        for i in 0..m { for j in 0..n { Y[i][j] = x[nq + i * n + j]; } }
        (Q, Y, x[nv - 1])
    };
    let A = A.clone(); let B = B.clone();
    let mut lmis: Vec<(usize, Box<dyn Fn(&[f64]) -> M>)> = vec![];
    let u1 = unpack.clone();
    lmis.push((n, Box::new(move |x| { let (Q, _, _) = u1(x); let mut F = z(n, n); for i in 0..n { for j in 0..n { F[i][j] = (if i == j {1.0} else {0.0}) - Q[i][j]; } } F })));
    let u2 = unpack.clone();
    lmis.push((n, Box::new(move |x| { let (Q, _, s) = u2(x); let mut F = Q.clone(); for i in 0..n { F[i][i] -= s; } F })));
    let u3 = unpack.clone();
    let k = if form == 3 { 3 * n } else { 2 * n };
    lmis.push((k, Box::new(move |x| {
        let (Q, Y, _) = u3(x);
        let mut Mm = z(n, n);
        for i in 0..n { for j in 0..n { let mut s = 0.0; for l in 0..n { s += A[i][l] * Q[l][j]; } for l in 0..m { s += B[i][l] * Y[l][j]; } Mm[i][j] = s; } }
        let mut F = z(k, k);
        for i in 0..n { for j in 0..n {
            F[i][j] = if form == 3 { Q[i][j] } else { (1.0 - sigma) * Q[i][j] };
            F[i][n + j] = Mm[i][j]; F[n + j][i] = Mm[i][j];
            F[n + i][n + j] = Q[i][j];
            if form == 3 { F[n + i][2 * n + j] = Q[i][j]; F[2 * n + j][n + i] = Q[i][j]; }
        } }
        if form == 3 { for i in 0..n { F[2 * n + i][2 * n + i] = 1.0 / sigma; } }
        F
    })));
    (nv, lmis)
}

fn solve(n: usize, m: usize, A: &M, B: &M, form: u8, sigma: f64) -> (f64, SolverStatus, u32, f64) {
    let t0 = Instant::now();
    let (nv, lmis) = build(n, m, A, B, form, sigma);
    let mut I = vec![]; let mut J = vec![]; let mut V = vec![]; let mut b = vec![]; let mut cones = vec![];
    let mut row = 0;
    let x0 = vec![0.0; nv];
    let s2 = 2f64.sqrt();
    for (k, f) in &lmis {
        let F0 = f(&x0);
        let mut r = row;
        for j in 0..*k { for i in 0..=j { b.push(if i == j { F0[i][j] } else { s2 * F0[i][j] }); r += 1; } }
        for v in 0..nv {
            let mut e = vec![0.0; nv]; e[v] = 1.0;
            let Fv = f(&e);
            let mut r = row;
            for j in 0..*k { for i in 0..=j { let d = Fv[i][j] - F0[i][j]; if d != 0.0 { I.push(r); J.push(v); V.push(-(if i == j { d } else { s2 * d })); } r += 1; } }
        }
        row = r;
        cones.push(PSDTriangleConeT(*k));
    }
    let Am = CscMatrix::new_from_triplets(row, nv, I, J, V);
    let P = CscMatrix::zeros((nv, nv));
    let mut q = vec![0.0; nv]; q[nv - 1] = -1.0;
    let settings = DefaultSettingsBuilder::default().verbose(false).build().unwrap();
    let mut solver = DefaultSolver::new(&P, &q, &Am, &b, &cones, settings).unwrap();
    solver.solve();
    (t0.elapsed().as_secs_f64() * 1e3, solver.solution.status, solver.info.iterations, solver.solution.x[nv - 1])
}

fn main() {
    let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    for &(n, m) in &[(4usize, 2usize), (12, 3)] {
        let A: M = (0..n).map(|i| (0..n).map(|j| (if i == j {1.0} else {0.0}) + 0.05 * r.random_range(-1.0..1.0)).collect()).collect();
        let B: M = (0..n).map(|_| (0..m).map(|_| 0.1 * r.random_range(-1.0..1.0)).collect()).collect();
        for form in [2u8, 3u8] {
            for _ in 0..3 {
                let (ms, st, it, s) = solve(n, m, &A, &B, form, 0.01);
                println!("n={n} form={form}: {ms:.2} ms {st:?} iters={it} s={s:.4e}");
            }
        }
    }
}
