//! End to end: clarabel's SDP path (PSD cones of size ≥ 4 go through ?syevr/?potrf/?gesdd/?gemm/...) links
//! against these symbols and solves a problem with a known optimum: min tr(C X) s.t. tr X = 1, X ⪰ 0 has the
//! value λ_min(C).

use crate::common;
use clarabel::algebra::*;
use clarabel::solver::*;
use common::*;
use lapack_faer as _;

#[test]
fn min_eigenvalue_sdp_matches_jacobi() {
    let mut r = rng(30);
    for &n in &[4usize, 6, 9] {
        let c = rand_sym(&mut r, n, n);
        let want = jacobi_eigenvalues(&c, n, n)[0];
        let nvec = n * (n + 1) / 2;
        // svec: upper triangle by columns, off-diagonals scaled by √2 (so <svec C, svec X> = tr(C X)).
        let mut q = Vec::with_capacity(nvec);
        let mut trace_row = Vec::with_capacity(nvec);
        for j in 0..n {
            for i in 0..=j {
                q.push(if i == j {
                    c[i + j * n]
                } else {
                    2f64.sqrt() * c[i + j * n]
                });
                trace_row.push(if i == j { 1.0 } else { 0.0 });
            }
        }
        // Rows 0..nvec: s = x ∈ PSD (A = -I, b = 0); last row: tr X = 1 (zero cone).
        let mut rows: Vec<Vec<f64>> = (0..nvec)
            .map(|i| (0..nvec).map(|j| if i == j { -1.0 } else { 0.0 }).collect())
            .collect();
        rows.push(trace_row);
        let a = CscMatrix::from(&rows);
        let mut b = vec![0.0; nvec];
        b.push(1.0);
        let p = CscMatrix::zeros((nvec, nvec));
        let cones = [PSDTriangleConeT(n), ZeroConeT(1)];
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .build()
            .unwrap();
        let mut solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings).unwrap();
        solver.solve();
        assert_eq!(solver.solution.status, SolverStatus::Solved, "n={n}");
        assert!(
            (solver.solution.obj_val - want).abs() < 1e-6,
            "n={n}: {} vs {want}",
            solver.solution.obj_val
        );
    }
}
